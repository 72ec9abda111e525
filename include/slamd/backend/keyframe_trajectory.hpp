#pragma once
// KeyframeAnchoredTrajectory: the full per-frame trajectory of a run, corrected through the back
// end. Each frame is stored as its odometry pose relative to its reference keyframe (the keyframe
// tracking measured it against, else the latest keyframe of its segment); the corrected
// trajectory composes the back end's corrected pose of that keyframe with the stored offset:
//   T_world_frame = T_world_keyframe(corrected) * T_world_keyframe(odometry)^-1 *
//   T_world_frame(odometry)
//
// Usage (one thread, no threads inside):
//   KeyframeAnchoredTrajectory trajectory;
//   for each OdometryResult r:
//     if (r.keyframe) { trajectory.addKeyframe(r.keyframe); backend.addKeyframe(r.keyframe); }
//     trajectory.addFrame(r);
//   Trajectory slam = trajectory.corrected(backend);   // T_world_camera per frame, seconds
//
// A keyframe the back end culled keeps its frames: its corrected pose is the one the back end
// gives it through the keyframe it was merged into.
//
// Frames before the first keyframe are skipped.

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "slamd/backend/backend.hpp"
#include "slamd/common/trajectory.hpp"

namespace slamd {

class KeyframeAnchoredTrajectory {
 public:
  void addKeyframe(const KeyframePtr& keyframe);
  /// Records the frame of one processFrame() result (after addKeyframe for its keyframe). A
  /// frame that took one of the map's keyframes as reference (OdometryStats::used_map_keyframe)
  /// places that keyframe anew: it and the frames measured against it after it are stored
  /// against the pose the frame's measurement gives it, not the pose it was made at.
  void addFrame(const OdometryResult& result) { addFrame(result, result.T_world_camera); }
  /// The same with the frame's pose from another estimator (the filter's), in the frame its
  /// keyframes' poses were given in.
  void addFrame(const OdometryResult& result, const SE3& T_world_camera);

  std::size_t size() const { return frames_.size(); }
  /// The frames as odometry reported them.
  Trajectory odometry() const;
  /// The frames through the keyframes' corrected poses.
  Trajectory corrected(const Backend& backend) const;

 private:
  struct Frame {
    double t_s = 0.0;
    std::size_t anchor = 0;                ///< index into anchors_
    SE3 T_world_camera = SE3::Identity();  ///< odometry
  };
  /// What a frame's pose is stored against: only the keyframe's odometry pose and segment (the
  /// keyframe itself, and its images, are not kept). A keyframe placed anew gets another.
  struct Anchor {
    std::int64_t keyframe_id = -1;
    std::int64_t segment = 0;
    SE3 T_world_camera = SE3::Identity();  ///< odometry
  };
  /// Appends an anchor; it becomes the keyframe's current one.
  std::size_t addAnchor(std::int64_t keyframe_id, std::int64_t segment, const SE3& T_world_camera);

  std::vector<Anchor> anchors_;
  std::unordered_map<std::int64_t, std::size_t> anchor_of_keyframe_;  ///< the current one
  std::size_t latest_anchor_ = 0;
  std::vector<Frame> frames_;
};

}  // namespace slamd
