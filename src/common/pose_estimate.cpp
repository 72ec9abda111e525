#include "slamd/common/pose_estimate.hpp"

namespace slamd {

const char* trackingStateName(TrackingState state) {
  switch (state) {
    case TrackingState::kNotInitialized:
      return "not_initialized";
    case TrackingState::kOk:
      return "ok";
    case TrackingState::kPredicted:
      return "predicted";
    case TrackingState::kLost:
      return "lost";
    case TrackingState::kRelocalized:
      return "relocalized";
    case TrackingState::kNotLocalized:
      return "not_localized";
  }
  return "?";
}

PoseEstimate transformedPose(const PoseEstimate& pose, const SE3& T_new_old) {
  PoseEstimate out = pose;
  out.T_world_camera = T_new_old * pose.T_world_camera;
  Matrix6d J = Matrix6d::Identity();
  J.topLeftCorner<3, 3>() = T_new_old.linear();
  out.covariance = J * pose.covariance * J.transpose();
  out.linear_velocity_world_mps = T_new_old.linear() * pose.linear_velocity_world_mps;
  return out;
}

}  // namespace slamd
