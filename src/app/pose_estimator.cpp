#include "slamd/app/pose_estimator.hpp"

namespace slamd {

PoseEstimator::PoseEstimator(const FilterConfig& config, VanishingPointSource vanishing_points)
    : config_(config), vanishing_point_source_(vanishing_points) {}

void PoseEstimator::reset() {
  filter_.reset();
  last_pose_ = PoseEstimate();
  covariance_last_measured_.reset();
  last_utime_ = 0;
}

EstimatedPacket PoseEstimator::process(TrackedPacket packet) {
  EstimatedPacket out;
  out.frame = std::move(packet.frame);
  out.odometry = std::move(packet.odometry);
  out.reset_epoch = packet.reset_epoch;
  out.pose = last_pose_;
  if (!out.frame || !out.odometry) return out;  // heartbeat

  const OdometryResult& odometry = *out.odometry;
  const RgbdFrame& frame = *out.frame;
  if (!filter_) filter_.emplace(config_, frame.intrinsics);
  FilterInput input;
  input.utime = odometry.utime;
  // The first frame defines the world frame: no motion to apply.
  input.T_prev_curr = last_utime_ > 0 ? odometry.T_prev_curr : SE3::Identity();
  input.covariance = last_utime_ > 0 ? odometry.covariance : Matrix6d::Identity() * 1e-12;
  input.dt_s = last_utime_ > 0 ? utimeToSeconds(odometry.utime - last_utime_) : 0.0;
  // (A covariance of the last measured frame implies an earlier frame: last_utime_ > 0.)
  if (odometry.tracking_state == TrackingState::kRelocalized && covariance_last_measured_) {
    // The step from the pose held through the loss to the relocalised one is applied exactly,
    // with the covariance of the last measured frame plus the measurement's (rotated into the
    // filter's convention: translation in the world frame).
    PoseEkf& ekf = filter_->ekf();
    const SE3 T_world_curr = normalizedSE3(ekf.T_world_camera() * input.T_prev_curr);
    Matrix6d J = Matrix6d::Identity();
    J.topLeftCorner<3, 3>() = T_world_curr.linear();
    const Matrix6d measurement = J * odometry.covariance_ref_curr * J.transpose();
    Matrix6d covariance = *covariance_last_measured_;
    if (measurement.allFinite()) covariance += measurement;
    ekf.setPose(T_world_curr, covariance);
    input.T_prev_curr = SE3::Identity();
    input.covariance = Matrix6d::Identity() * 1e-12;
  }
  input.depth_m = frame.depth_m;  // plane axes (filter.surface_axes) are detected here
  if (vanishing_point_source_ == VanishingPointSource::kDetectHere) {
    input.gray = frame.gray;
  } else {
    input.detection = std::move(packet.vanishing_point);
  }
  const FilterOutput filtered = filter_->process(input);
  if (odometry.tracking_state == TrackingState::kOk ||
      odometry.tracking_state == TrackingState::kRelocalized) {
    covariance_last_measured_ = filter_->ekf().poseCovariance();
  }
  if (filtered.vanishing_point && filtered.update) {
    out.vanishing_point = VanishingPointReport{*filtered.vanishing_point, *filtered.update};
  }

  PoseEstimate& pose = out.pose;
  pose = filtered.pose;
  pose.utime = odometry.utime;
  pose.sequence = sequence_++;
  pose.tracking_state = odometry.tracking_state;
  pose.source = config_.enabled ? PoseSource::kFilter : PoseSource::kOdometry;
  if (input.dt_s > 0.0) {
    const SE3& previous = last_pose_.T_world_camera;
    pose.linear_velocity_world_mps =
        (pose.T_world_camera.translation() - previous.translation()) / input.dt_s;
    pose.angular_velocity_camera_radps =
        logSE3(previous.inverse() * pose.T_world_camera).tail<3>() / input.dt_s;
  }
  last_pose_ = pose;
  last_utime_ = odometry.utime;
  return out;
}

}  // namespace slamd
