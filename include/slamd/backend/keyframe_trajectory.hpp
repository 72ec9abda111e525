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
  /// Records the frame of one processFrame() result (after addKeyframe for its keyframe).
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
    std::int64_t keyframe_id = -1;
    SE3 T_world_camera = SE3::Identity();  ///< odometry
  };
  /// What a frame's pose is stored against: only the keyframe's odometry pose and segment (the
  /// keyframe itself, and its images, are not kept).
  struct Anchor {
    std::int64_t segment = 0;
    SE3 T_world_camera = SE3::Identity();  ///< odometry
  };
  std::unordered_map<std::int64_t, Anchor> keyframes_;
  std::int64_t latest_id_ = -1;
  std::vector<Frame> frames_;
};

}  // namespace slamd
