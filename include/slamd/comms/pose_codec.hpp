#pragma once
// Conversions between PoseEstimate and the pose messages slamd publishes.

#include "slamd/common/pose_estimate.hpp"
#include "bot_core/pose_t.hpp"
#include "slamd/pose_t.hpp"

namespace slamd {

slamd::pose_t toPoseMessage(const PoseEstimate& pose);
PoseEstimate fromPoseMessage(const slamd::pose_t& message);
/// bot_core.pose_t for existing LCM tools (no covariance; accel zero: not estimated).
bot_core::pose_t toBotCorePose(const PoseEstimate& pose);

}  // namespace slamd
