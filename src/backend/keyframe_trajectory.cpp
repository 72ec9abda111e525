#include "slamd/backend/keyframe_trajectory.hpp"

#include "slamd/common/time.hpp"

namespace slamd {

void KeyframeAnchoredTrajectory::addKeyframe(const KeyframePtr& keyframe) {
  if (keyframe == nullptr) return;
  keyframes_[keyframe->id] = Anchor{keyframe->segment, keyframe->T_world_camera};
  latest_id_ = keyframe->id;
}

void KeyframeAnchoredTrajectory::addFrame(const OdometryResult& result, const SE3& T_world_camera) {
  if (latest_id_ < 0) return;
  std::int64_t anchor = latest_id_;
  const auto it = keyframes_.find(result.reference_keyframe_id);
  if (it != keyframes_.end() && it->second.segment == result.segment) anchor = it->first;
  frames_.push_back({utimeToSeconds(result.utime), anchor, T_world_camera});
}

Trajectory KeyframeAnchoredTrajectory::odometry() const {
  Trajectory out;
  out.reserve(frames_.size());
  for (const Frame& f : frames_) out.push_back({f.t_s, f.T_world_camera});
  return out;
}

Trajectory KeyframeAnchoredTrajectory::corrected(const Backend& backend) const {
  Trajectory out;
  out.reserve(frames_.size());
  for (const Frame& f : frames_) {
    const Anchor& kf = keyframes_.at(f.keyframe_id);
    const SE3 T_world_kf =
        backend.hasKeyframe(f.keyframe_id) ? backend.pose(f.keyframe_id) : kf.T_world_camera;
    out.push_back({f.t_s, T_world_kf * kf.T_world_camera.inverse() * f.T_world_camera});
  }
  return out;
}

}  // namespace slamd
