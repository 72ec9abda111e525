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
// The corridor mode (filter.planes.*, issue 23 item 4): a frame tracked with fewer than
// corridor_min_inliers inliers (or by dense alignment, or not measured at all) switches it on;
// corridor_exit_frames frames in a row with enough inliers switch it off. While it is on, the
// plane-segmentation thread segments each frame into planes. Here a frame's planes are registered
// by plane ICP (planes::registerPlanes) against those of the frame tracking measured it from
// (its reference: a keyframe, or the previous frame), or when that one was not segmented, against
// the first segmented frame measured from the same reference (the anchor). The plane measurement
// of T_ref_curr is fused with tracking's (T_ref_curr, covariance_ref_curr) by information
// (fuseMotion): what the planes measure (across a corridor) comes from them, what they leave free
// (along it) stays tracking's. The filter's increment is then the step between the fused
// T_ref_prev and T_ref_curr; a frame not fused keeps tracking's increment, so the previous
// frame's correction carries on instead of being undone at once. Fusing against the reference
// rather than the previous frame keeps the plane errors from adding up: like tracking's own,
// successive frames' errors against one reference cancel in the increments instead of accumulating
// frame by frame (docs/planes.md). Unless filter.planes.fuse_rotation, only the translation is
// fused, the rotation marginalised out. A plane measurement that disagrees with tracking's beyond
// the gate is not fused (counted).
//
// No threads inside; owned by the filter thread. process() never throws on bad data.

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>

#include "slamd/app/packets.hpp"
#include "slamd/filter/filter_config.hpp"
#include "slamd/filter/vanishing_point_filter.hpp"

namespace slamd {

/// The corridor mode's counts: written by the filter thread, read by any.
struct CorridorModeStats {
  std::atomic<bool> on{false};
  std::atomic<std::uint64_t> switched_on{0};  ///< times the mode came on
  std::atomic<std::uint64_t> frames{0};       ///< frames filtered with the mode on
  std::atomic<std::uint64_t> fused{0};        ///< plane measurements fused
  std::atomic<std::uint64_t> gated{0};        ///< plane measurements too far from tracking's
  std::atomic<std::uint64_t> unmatched{0};    ///< no segmented reference or anchor to register with
  std::atomic<std::uint64_t> nis_sum_milli{0};         ///< sum of the fused increments' NIS x 1000
  std::atomic<std::uint64_t> registrations_failed{0};  ///< plane ICP failed
};

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
  bool corridorModeOn() const { return corridor_.on.load(std::memory_order_relaxed); }
  const CorridorModeStats& corridorMode() const { return corridor_; }
  /// The EKF's counters since the first frame or the last reset (zero before the first frame).
  /// Owned by the filter thread: read them only once it has stopped.
  EkfCounters ekfCounters() const { return filter_ ? filter_->ekf().counters() : EkfCounters{}; }

 private:
  /// Updates the corridor mode from this frame's tracking.
  void updateCorridorMode(const OdometryResult& odometry);
  /// With the frame's planes: registers them against its reference's (or the reference's
  /// anchor's), fuses the result with tracking's T_ref_curr, and sets input's increment from the
  /// fused poses relative to the reference (see above). Without: forgets the fused pose.
  void fusePlaneOdometry(const std::shared_ptr<const planes::PlaneSegmentation>& planes,
                         const OdometryResult& odometry, const CameraIntrinsics& intrinsics,
                         FilterInput& input);

  FilterConfig config_;
  VanishingPointSource vanishing_point_source_;
  std::optional<VanishingPointFilter> filter_;  ///< created at the first frame (intrinsics)
  PoseEstimate last_pose_;
  /// The filter's pose covariance at the last frame tracking measured (kOk or kRelocalized).
  std::optional<Matrix6d> covariance_last_measured_;
  Utime last_utime_ = 0;
  std::int64_t sequence_ = 0;
  CorridorModeStats corridor_;
  /// A segmented frame that later frames' planes are registered against.
  struct PlaneAnchor {
    Utime utime = 0;      ///< the frame's
    Utime ref_utime = 0;  ///< the reference tracking measured the frame from
    SE3 T_ref_frame;      ///< the fused pose relative to that reference
    std::shared_ptr<const planes::PlaneSegmentation> planes;
  };
  /// Keyframes' and the first frame of each reference's (newest last), then the previous frame.
  std::deque<PlaneAnchor> plane_anchors_;
  std::optional<PlaneAnchor> previous_planes_;
  static constexpr std::size_t kMaxPlaneAnchors = 16;
  /// The previous frame's pose relative to its reference as given to the filter (fused or
  /// tracking's), while frames are segmented and measured.
  struct ReferencePose {
    Utime utime = 0;
    Utime ref_utime = 0;
    SE3 T_ref_frame;
  };
  std::optional<ReferencePose> previous_reference_pose_;
  int frames_with_features_ = 0;  ///< in a row, while the corridor mode is on
};

}  // namespace slamd
