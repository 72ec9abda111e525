#pragma once
// Backend: the keyframe graph with loop closing. It takes keyframes from visual odometry one at a
// time, links each to the previous one with an odometry edge, looks for loops (LoopDetector) and,
// when one is found, adds the loop edge and re-optimises the pose graph (PoseGraph, CHOLMOD).
//
// Usage (one thread owns it, the back-end thread; there are no threads inside):
//   Backend backend(BackendConfig::load(config), vocabulary);
//   on each OdometryResult r with r.keyframe:
//     BackendUpdate u = backend.addKeyframe(r.keyframe);
//     if (u.optimized) {
//       // corrected keyframe poses for the map rebuild; correction for the live pose:
//       for (auto& [id, T_world_kf] : u.corrected_poses) mapper.setKeyframePose(id, T_world_kf);
//       T_world_camera_corrected = u.T_world_odometry * T_world_camera_odometry;
//     }
//
// Frames: the world frame is the first keyframe's (visual odometry's world). Odometry poses are
// the keyframes' T_world_camera as tracking made them; corrected poses are the optimised
// T_world_camera of the same keyframes. T_world_odometry = T_world_latest_corrected *
// T_world_latest_odometry^-1 maps odometry-world points into the corrected world, the correction
// to apply to any pose tracking reports after the latest keyframe.
//
// Odometry edges: consecutive keyframes of one tracking segment, measurement
// T_prev_curr = T_world_prev^-1 * T_world_curr from the odometry poses, standard deviation
// odometry_sigma_ratio * distance (+ 5 mm) per axis and odometry_sigma_rad per axis. A keyframe
// starting a new segment (after LOST) is tied to the previous one by a very weak edge only, so a
// later loop can place it.

#include <cstdint>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/loop_detector.hpp"
#include "slamd/backend/pose_graph.hpp"
#include "slamd/tracking/visual_odometry.hpp"

namespace slamd {

struct BackendUpdate {
  std::int64_t keyframe_id = -1;
  LoopDetection loop;               ///< the loop search for this keyframe
  bool optimized = false;           ///< a loop was added and the graph re-optimised
  PoseGraphResult optimization;     ///< valid when optimized
  /// Every keyframe's corrected T_world_camera (metres), when optimized.
  std::vector<std::pair<std::int64_t, SE3>> corrected_poses;
  /// Correction from the odometry world to the corrected world (see the class comment).
  SE3 T_world_odometry = SE3::Identity();
};

class Backend {
 public:
  Backend(const BackendConfig& config, std::shared_ptr<const Vocabulary> vocabulary);

  /// Adds the next keyframe (ids increasing). Never throws on bad data; a keyframe without usable
  /// descriptors still joins the graph (with its odometry edge), it just cannot close loops.
  BackendUpdate addKeyframe(const KeyframePtr& keyframe);

  /// Current (corrected) T_world_camera of a keyframe; the odometry pose before any loop.
  SE3 pose(std::int64_t keyframe_id) const { return graph_.pose(keyframe_id); }
  const PoseGraph& graph() const { return graph_; }
  const LoopDetector& loopDetector() const { return detector_; }
  LoopDetector& loopDetector() { return detector_; }
  int numLoops() const { return num_loops_; }

 private:
  Matrix6d odometryInformation(const SE3& T_prev_curr) const;

  BackendConfig config_;
  PoseGraphOptions options_;
  PoseGraph graph_;
  LoopDetector detector_;
  KeyframePtr previous_;  ///< the latest keyframe added
  int num_loops_ = 0;
};

}  // namespace slamd
