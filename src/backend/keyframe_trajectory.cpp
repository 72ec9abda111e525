#include "slamd/backend/keyframe_trajectory.hpp"

#include "slamd/common/time.hpp"

namespace slamd {

void KeyframeAnchoredTrajectory::addKeyframe(const KeyframePtr& keyframe) {
  if (keyframe == nullptr) return;
  latest_anchor_ = addAnchor(keyframe->id, keyframe->segment, keyframe->T_world_camera);
}

std::size_t KeyframeAnchoredTrajectory::addAnchor(std::int64_t keyframe_id, std::int64_t segment,
                                                  const SE3& T_world_camera) {
  anchors_.push_back(Anchor{keyframe_id, segment, T_world_camera});
  anchor_of_keyframe_[keyframe_id] = anchors_.size() - 1;
  return anchors_.size() - 1;
}

void KeyframeAnchoredTrajectory::addFrame(const OdometryResult& result, const SE3& T_world_camera) {
  if (anchors_.empty()) return;  // before the first keyframe
  std::size_t anchor = latest_anchor_;
  if (result.stats.used_map_keyframe && result.reference_keyframe_id >= 0) {
    anchor = addAnchor(result.reference_keyframe_id, result.segment,
                       T_world_camera * result.T_ref_curr.inverse());
  } else {
    const auto it = anchor_of_keyframe_.find(result.reference_keyframe_id);
    if (it != anchor_of_keyframe_.end() && anchors_[it->second].segment == result.segment) {
      anchor = it->second;
    }
  }
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
    const Anchor& kf = anchors_[f.anchor];
    const SE3 T_world_kf =
        backend.hasKeyframe(kf.keyframe_id) ? backend.pose(kf.keyframe_id) : kf.T_world_camera;
    out.push_back({f.t_s, T_world_kf * kf.T_world_camera.inverse() * f.T_world_camera});
  }
  return out;
}

}  // namespace slamd
