#pragma once
// BackendStage: the daemon's back-end thread step. It sees every filtered frame; keyframes go to
// the Backend (loop closing, relocalisation, pose-graph optimisation) with the filter's pose, so
// the graph lives in the frame the filter integrates in (the "uncorrected world"). Each
// optimisation becomes a BackendCorrection: the transform from the uncorrected world to the
// corrected one (the publisher applies it to every later pose, like ROS's map -> odom), the
// corrected keyframe poses (the mapper moves the keyframe clouds that moved) and the
// optimised keyframe trajectory (published on SLAMD_KEYFRAMES).
//
// Every tracked frame is remembered as (keyframe, pose relative to it), so that at the end the
// whole trajectory can be written at its optimised poses, not only the keyframes. The back end
// keeps keyframes without their images (compactKeyframe); culled keyframes leave the graph and
// the published keyframe list, their frames stay anchored through the keyframe that covers them.
//
// Whole-graph optimisations (backend.full_optimization_in_background) run on a
// BackgroundOptimizer's thread: process() hands out the Backend's job and, on a later call (every
// frame and heartbeat calls it), merges the result and returns its correction. finish() waits
// for the job in flight and runs any still wanted, so the final poses are the whole graph's.
// Without it, the stage has no threads inside and is deterministic.
//
// Owned by the back-end thread, then by the control thread after the pipeline stopped.
// process() never throws on bad data.

#include <cstdint>
#include <memory>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include "slamd/app/packets.hpp"
#include "slamd/backend/backend.hpp"
#include "slamd/backend/background_optimizer.hpp"
#include "slamd/backend/keyframe_trajectory.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/comms/pose_codec.hpp"

namespace slamd {

/// What one pose-graph optimisation changes downstream.
struct BackendCorrection {
  /// Uncorrected world (filter) -> corrected world, for every pose after this keyframe.
  SE3 T_world_uncorrected = SE3::Identity();
  /// Every keyframe's optimised T_world_camera, for Mapper::correctKeyframePoses().
  std::vector<std::pair<std::int64_t, SE3>> keyframe_poses;
  /// The message for SLAMD_KEYFRAMES.
  KeyframeTrajectory trajectory;
  bool relocalized = false;  ///< a lost tracking segment was put back into the map
  /// The newest keyframe is in the map's frame: false while its tracking segment (the run's
  /// first in a loaded session, or one after a loss) has not been relocalised into the map.
  bool map_frame_known = true;
  std::int64_t newest_segment = -1;  ///< the newest keyframe's tracking segment
};

struct BackendStageStats {
  std::int64_t keyframes = 0;         ///< in the graph now (culled ones not counted)
  std::int64_t culled_keyframes = 0;  ///< redundant keyframes removed
  std::int64_t keyframe_bytes = 0;    ///< held by the back end's keyframes (keyframeBytes)
  std::int64_t loops = 0;
  std::int64_t local_edges = 0;
  std::int64_t relocalizations = 0;
  std::int64_t optimizations = 0;
  double last_optimization_ms = 0.0;
  /// Longest optimisation in the back-end thread (a local window, or a whole graph when not in
  /// the background).
  double max_optimization_ms = 0.0;
  /// With a restored session: frames this run tracked before the keyframe that put it in the
  /// loaded map's frame (0 = the first frame's keyframe did); -1 while not localised or without
  /// a session.
  std::int64_t frames_before_localization = -1;
  std::int64_t background_optimizations = 0;    ///< whole-graph ones merged from the background
  double max_background_optimization_ms = 0.0;  ///< their longest (on the worker thread)
};

class BackendStage {
 public:
  BackendStage(const BackendConfig& config, std::shared_ptr<const Vocabulary> vocabulary);

  /// Takes the next filtered frame (heartbeats and lost frames are ignored). Returns a correction
  /// when this frame's keyframe made the back end re-optimise.
  std::optional<BackendCorrection> process(const EstimatedPacket& packet);

  /// Memory pressure (common/memory_pressure.hpp): the Backend culls harder, and from kNear on
  /// new keyframes are kept without the image patch alignment uses (about half of a keyframe's
  /// bytes; their matches are then not refined to sub-pixel).
  void setMemoryPressure(MemoryPressure pressure);

  /// End of the run: waits for a whole-graph optimisation in flight and runs any still wanted,
  /// so that optimizedTrajectory() and backend() hold the final poses.
  void finish();

  /// Every tracked frame seen so far, at its keyframe's current (optimised) pose composed with
  /// the frame's pose relative to that keyframe; T_world_camera in the corrected world.
  Trajectory optimizedTrajectory() const;

  /// Loads a session's back end (Backend::restore) into the fresh stage: the loaded keyframes
  /// join the published keyframe list; RESET restores it again. Throws as Backend::restore.
  void restore(std::shared_ptr<const BackendSnapshot> snapshot, bool fix_loaded_keyframes);

  /// Forgets everything (the RESET command); a restored session is restored again.
  void reset();

  const BackendStageStats& stats() const { return stats_; }
  const Backend& backend() const { return *backend_; }
  /// The newest keyframe this run added (culled or not), -1 before the first.
  std::int64_t latestKeyframeId() const { return latest_keyframe_id_; }

 private:
  /// The keyframe part of process(): a correction when this frame's keyframe re-optimised.
  std::optional<BackendCorrection> processKeyframe(const EstimatedPacket& packet);
  BackendCorrection makeCorrection(const BackendUpdate& update, Utime utime);
  /// Merges a finished whole-graph optimisation; its correction, if it moved anything.
  std::optional<BackendCorrection> mergeFullOptimization(const FullOptimizationJob& job,
                                                         Utime utime);
  /// Earlier keyframes the back end culled into a new one leave the keyframe list and the
  /// counts.
  void forgetCulledEarlierKeyframes(const std::vector<std::int64_t>& ids);

  BackendConfig config_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  std::unique_ptr<Backend> backend_;
  /// Whole-graph optimisations off the back-end thread (null when not in the background).
  std::unique_ptr<BackgroundOptimizer> optimizer_;
  /// Every tracked frame with the filter's pose, anchored to its keyframe.
  KeyframeAnchoredTrajectory frames_;
  std::vector<KeyframePoseEntry> keyframes_;  ///< id order; poses filled in on demand
  std::unordered_map<std::int64_t, std::int64_t> keyframe_bytes_;  ///< this run's, by id
  std::int64_t latest_keyframe_id_ = -1;
  std::int64_t frames_seen_ = 0;  ///< tracked frames of this run (restored sessions)
  std::shared_ptr<const BackendSnapshot> restored_;  ///< the session loaded, if any
  bool fix_restored_keyframes_ = true;
  MemoryPressure memory_pressure_ = MemoryPressure::kNone;
  Utime latest_keyframe_utime_ = 0;
  std::int64_t sequence_ = 0;
  BackendStageStats stats_;
};

}  // namespace slamd
