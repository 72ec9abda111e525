#pragma once
// PoseEstimate: a stamped camera pose with uncertainty, as produced by odometry, the filter or
// the back end, and as published on SLAMD_POSE.

#include <cstdint>
#include <string>

#include "slamd/common/se3.hpp"
#include "slamd/common/time.hpp"

namespace slamd {

/// Explicit tracking state (ORB-SLAM's idea worth keeping); values match pose_t.TRACKING_*.
enum class TrackingState : std::int8_t {
  kNotInitialized = 0,
  kOk = 1,
  kPredicted = 2,  ///< no measurement for this frame: constant-velocity prediction
  kLost = 3,
  kRelocalized = 4,
  /// Tracking works, but a session was loaded (--session-in) and the pose is not yet localised
  /// in its map: it is in this run's own frame, which starts at the first camera pose.
  kNotLocalized = 5,
};

/// Which estimator produced a pose; values match pose_t.SOURCE_*.
enum class PoseSource : std::int8_t { kOdometry = 0, kFilter = 1, kOptimized = 2 };

const char* trackingStateName(TrackingState state);

struct PoseEstimate {
  Utime utime = 0;            ///< capture time of the frame
  std::int64_t sequence = 0;  ///< +1 per published pose
  std::string parent_frame = "world";
  std::string child_frame = "camera";
  SE3 T_world_camera = SE3::Identity();
  /// Covariance, order x y z rx ry rz: translation in metres^2 (world frame), rotation in
  /// radians^2 as a local (right) perturbation in the camera frame.
  Matrix6d covariance = Matrix6d::Identity() * 1e-6;
  Eigen::Vector3d linear_velocity_world_mps = Eigen::Vector3d::Zero();
  Eigen::Vector3d angular_velocity_camera_radps = Eigen::Vector3d::Zero();
  TrackingState tracking_state = TrackingState::kNotInitialized;
  PoseSource source = PoseSource::kOdometry;
};

/// The same pose expressed in another world frame: T_new_old * T_world_camera, e.g. the back end's
/// loop-closure correction applied to a filtered pose. The translation covariance and the linear
/// velocity (world frame) rotate with the frame; the rotation covariance and angular velocity
/// (camera frame) do not change.
PoseEstimate transformedPose(const PoseEstimate& pose, const SE3& T_new_old);

}  // namespace slamd
