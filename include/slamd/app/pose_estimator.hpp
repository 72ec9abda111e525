#pragma once
// PoseEstimator: the filter thread's algorithm. Turns each odometry result into the pose slamd
// publishes: with the filter enabled, the EKF is predicted with the odometry increment
// T_prev_curr and its covariance, then (optionally) corrected by the frame's vanishing point;
// with it disabled, increments are chained. Either way the world frame survives tracking loss:
// a new odometry segment continues from the last published pose instead of jumping back to the
// origin.
//
// No threads inside; owned by the filter thread. process() never throws on bad data.

#include <optional>

#include "slamd/app/packets.hpp"
#include "slamd/filter/filter_config.hpp"

namespace slamd {

class PoseEstimator {
 public:
  explicit PoseEstimator(const FilterConfig& config);

  EstimatedPacket process(TrackedPacket packet);
  /// Forgets the state (RESET command); the next frame starts again at the identity.
  void reset();
  /// Replaces the current pose estimate by a corrected one (back end); keeps the covariance.
  void applyCorrection(const SE3& T_corrected_world);

  const EkfCounters* ekfCounters() const { return ekf_ ? &ekf_->counters() : nullptr; }
  const FilterConfig& config() const { return config_; }

 private:
  FilterConfig config_;
  std::optional<PoseEkf> ekf_;
  std::optional<VanishingPointDetector> detector_;
  bool initialized_ = false;
  SE3 T_world_camera_ = SE3::Identity();  ///< last published pose (chained mode and velocities)
  Matrix6d covariance_ = Matrix6d::Zero();
  Utime last_utime_ = 0;
  std::int64_t sequence_ = 0;
};

}  // namespace slamd
