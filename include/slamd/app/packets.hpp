#pragma once
// What flows between the daemon's threads. Every packet is immutable once pushed and carries the
// frame it came from; a packet without a frame is a heartbeat, sent by the capture thread when no
// frame arrived for a while (paused, waiting for a live source) so that downstream stages still
// wake up to serve commands such as SAVE_MAP.
//
// reset_epoch: the number of RESET commands issued before the packet was captured. It travels
// with the packet through every stage, which resets when it first sees a newer epoch (see
// stage_steps.hpp).

#include <cstdint>
#include <memory>
#include <optional>

#include "slamd/common/pose_estimate.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/filter/pose_ekf.hpp"
#include "slamd/filter/vanishing_point_detector.hpp"
#include "slamd/filter/vanishing_point_filter.hpp"
#include "slamd/planes/plane_segmenter.hpp"
#include "slamd/tracking/visual_odometry.hpp"

namespace slamd {

/// capture -> tracking
struct CapturePacket {
  RgbdFramePtr frame;  ///< null: heartbeat
  std::uint64_t reset_epoch = 0;
  bool isHeartbeat() const { return !frame; }
};

/// plane-segmentation thread -> filter thread: one per frame; the frame's planes only in the
/// corridor mode.
struct PlaneSegmentationPacket {
  Utime utime = 0;                                          ///< capture time of the frame
  std::shared_ptr<const planes::PlaneSegmentation> planes;  ///< null: not segmented
};

/// tracking -> filter
struct TrackedPacket {
  RgbdFramePtr frame;                      ///< null: heartbeat
  std::optional<OdometryResult> odometry;  ///< set for every frame
  /// The frame's vanishing point, detected on the vanishing-point thread in parallel with
  /// tracking; joined to the packet by the filter thread (empty when that thread is off or its
  /// result was late).
  std::optional<VanishingPoint> vanishing_point;
  /// The frame's planes (the corridor mode), joined the same way.
  std::optional<PlaneSegmentationPacket> plane_segmentation;
  std::uint64_t reset_epoch = 0;
  bool isHeartbeat() const { return !frame; }
};

/// vanishing-point thread -> filter thread
struct VanishingPointPacket {
  Utime utime = 0;  ///< capture time of the frame it was detected in
  VanishingPoint detection;
};

/// filter -> publisher, mapping, back end
struct EstimatedPacket {
  /// Null in a heartbeat, and in the back end's copy of a frame that is not a keyframe (its queue
  /// keeps only what the back end uses: odometry and pose; a keyframe keeps its images).
  RgbdFramePtr frame;
  std::optional<OdometryResult> odometry;  ///< set for every frame, empty in a heartbeat
  PoseEstimate pose;                       ///< the pose slamd publishes for this frame
  std::optional<VanishingPointReport> vanishing_point;
  std::uint64_t reset_epoch = 0;
  bool isHeartbeat() const { return !frame && !odometry; }
};

}  // namespace slamd
