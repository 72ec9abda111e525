#include "slamd/app/pose_estimator.hpp"

#include "slamd/common/log.hpp"

namespace slamd {

PoseEstimator::PoseEstimator(const FilterConfig& config) : config_(config) {}

void PoseEstimator::reset() {
  ekf_.reset();
  detector_.reset();
  initialized_ = false;
  T_world_camera_ = SE3::Identity();
  covariance_ = Matrix6d::Zero();
  last_utime_ = 0;
}

void PoseEstimator::applyCorrection(const SE3& T_corrected_world) {
  T_world_camera_ = T_corrected_world * T_world_camera_;
  if (ekf_) ekf_->applyCorrection(T_corrected_world);
}

EstimatedPacket PoseEstimator::process(TrackedPacket packet) {
  EstimatedPacket out;
  out.frame = std::move(packet.frame);
  out.odometry = std::move(packet.odometry);
  out.pose.T_world_camera = T_world_camera_;
  out.pose.covariance = covariance_;
  if (!out.frame || !out.odometry) return out;  // heartbeat

  const OdometryResult& odometry = *out.odometry;
  const RgbdFrame& frame = *out.frame;
  const double dt_s = last_utime_ > 0 ? utimeToSeconds(odometry.utime - last_utime_) : 0.0;
  const SE3 T_world_previous = T_world_camera_;

  if (!initialized_) {
    // The world frame is the first camera frame.
    T_world_camera_ = SE3::Identity();
    if (config_.enabled) {
      ekf_.emplace(config_, frame.intrinsics);
      Matrix6d initial = Matrix6d::Zero();
      initial.diagonal().head<3>().setConstant(config_.initial_translation_sigma_m *
                                               config_.initial_translation_sigma_m);
      initial.diagonal().tail<3>().setConstant(config_.initial_rotation_sigma_rad *
                                               config_.initial_rotation_sigma_rad);
      ekf_->reset(T_world_camera_, initial);
      if (config_.vanishing_points) detector_.emplace(frame.intrinsics, config_.vp);
    }
    initialized_ = true;
  } else if (ekf_) {
    ekf_->predict(odometry.T_prev_curr, odometry.covariance, dt_s);
    T_world_camera_ = ekf_->T_world_camera();
  } else {
    T_world_camera_ = normalizedSE3(T_world_camera_ * odometry.T_prev_curr);
    covariance_ += odometry.covariance;  // first-order growth, good enough when not filtering
  }

  if (ekf_ && detector_ && !frame.gray.empty()) {
    VanishingPointReport report;
    report.detection = detector_->detect(frame.gray);
    if (report.detection.status == VanishingPointStatus::kOk) {
      report.update =
          ekf_->updateVanishingPoint(report.detection.pixel, report.detection.pixel_covariance);
      T_world_camera_ = ekf_->T_world_camera();
    }
    out.vanishing_point = report;
  }
  if (ekf_) covariance_ = ekf_->poseCovariance();

  PoseEstimate& pose = out.pose;
  pose.utime = odometry.utime;
  pose.sequence = sequence_++;
  pose.T_world_camera = T_world_camera_;
  pose.covariance = covariance_;
  pose.tracking_state = odometry.tracking_state;
  pose.source = ekf_ ? PoseSource::kFilter : PoseSource::kOdometry;
  if (dt_s > 0.0) {
    const Vector6d twist = logSE3(T_world_previous.inverse() * T_world_camera_) / dt_s;
    pose.linear_velocity_world_mps = (T_world_camera_.translation() - T_world_previous.translation()) / dt_s;
    pose.angular_velocity_camera_radps = twist.tail<3>();
  }
  last_utime_ = odometry.utime;
  return out;
}

}  // namespace slamd
