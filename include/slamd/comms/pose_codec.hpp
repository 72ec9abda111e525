#pragma once
// Conversions between PoseEstimate and the pose messages slamd publishes.

#include <string>
#include <vector>

#include "bot_core/pose_t.hpp"
#include "slamd/common/pose_estimate.hpp"
#include "slamd/keyframe_trajectory_t.hpp"
#include "slamd/pose_t.hpp"

namespace slamd {

slamd::pose_t toPoseMessage(const PoseEstimate& pose);
PoseEstimate fromPoseMessage(const slamd::pose_t& message);
/// bot_core.pose_t for existing LCM tools (no covariance; accel zero: not estimated).
bot_core::pose_t toBotCorePose(const PoseEstimate& pose);
/// The pose of a bot_core.pose_t: position, orientation and velocities; it carries no covariance
/// (left at PoseEstimate's default), tracking state or sequence (both zero).
PoseEstimate fromBotCorePose(const bot_core::pose_t& message);

/// One pose as a CSV line (no newline) under kPoseCsvHeader: utime, sequence, position,
/// quaternion (w x y z), the six covariance diagonal entries, tracking state name and source.
std::string formatPoseCsv(const PoseEstimate& pose);
extern const char* const kPoseCsvHeader;

/// One keyframe's optimised pose.
struct KeyframePoseEntry {
  std::int64_t keyframe_id = 0;
  Utime utime = 0;
  std::int64_t segment = 0;
  SE3 T_world_camera = SE3::Identity();
};

/// The back end's optimised keyframe trajectory (SLAMD_KEYFRAMES).
struct KeyframeTrajectory {
  Utime utime = 0;
  std::int64_t sequence = 0;
  std::string frame_id = "world";
  /// uncorrected world -> frame_id (see keyframe_trajectory_t)
  SE3 T_world_uncorrected = SE3::Identity();
  int num_loops = 0;
  int num_relocalizations = 0;
  double optimization_ms = 0.0;
  std::vector<KeyframePoseEntry> keyframes;  ///< id order
};

slamd::keyframe_trajectory_t toKeyframeTrajectoryMessage(const KeyframeTrajectory& trajectory);
KeyframeTrajectory fromKeyframeTrajectoryMessage(const slamd::keyframe_trajectory_t& message);

}  // namespace slamd
