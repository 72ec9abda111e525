#pragma once
// PoseEstimator: the daemon's filter-thread step. Adapts each odometry result to the filter
// (VanishingPointFilter: EKF predicted by the odometry increment, corrected by the frame's
// vanishing point; or plain chaining when filter.enabled is false) and fills in what the
// published pose needs besides: timestamps, sequence, tracking state and velocities.
//
// The world frame (the first camera frame) survives tracking loss: a new odometry segment
// continues from the last pose, because the filter only ever sees increments. A frame tracking
// relocalised against a keyframe from before the loss is as certain as the filter was at the
// last measured frame (plus the measurement): the covariance the loss accumulated is dropped, so
// that no later correction (a vanishing point) can swing a pose that is known again.
//
// No threads inside; owned by the filter thread. process() never throws on bad data.

#include <optional>

#include "slamd/app/packets.hpp"
#include "slamd/filter/filter_config.hpp"
#include "slamd/filter/vanishing_point_filter.hpp"

namespace slamd {

/// Where the filter's vanishing points come from.
enum class VanishingPointSource {
  kDetectHere,   ///< process() runs the detector on the frame's grey image
  kPrecomputed,  ///< only TrackedPacket::vanishing_point (the daemon's own thread) is used
};

class PoseEstimator {
 public:
  explicit PoseEstimator(const FilterConfig& config,
                         VanishingPointSource vanishing_points = VanishingPointSource::kDetectHere);

  EstimatedPacket process(TrackedPacket packet);
  /// Forgets the state (RESET command); the next frame starts again at the identity.
  void reset();

 private:
  FilterConfig config_;
  VanishingPointSource vanishing_point_source_;
  std::optional<VanishingPointFilter> filter_;  ///< created at the first frame (intrinsics)
  PoseEstimate last_pose_;
  /// The filter's pose covariance at the last frame tracking measured (kOk or kRelocalized).
  std::optional<Matrix6d> covariance_last_measured_;
  Utime last_utime_ = 0;
  std::int64_t sequence_ = 0;
};

}  // namespace slamd
