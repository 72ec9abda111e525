#include "slamd/app/backend_stage.hpp"

#include <algorithm>
#include <unordered_set>

#include "slamd/common/log.hpp"

namespace slamd {

namespace {
constexpr const char* kLog = "backend";
}  // namespace

BackendStage::BackendStage(const BackendConfig& config,
                           std::shared_ptr<const Vocabulary> vocabulary)
    : config_(config),
      vocabulary_(std::move(vocabulary)),
      backend_(std::make_unique<Backend>(config_, vocabulary_)) {
  backend_->setFullOptimizationDeferred(config_.full_optimization_in_background);
  if (config_.full_optimization_in_background) {
    optimizer_ = std::make_unique<BackgroundOptimizer>();
  }
}

void BackendStage::reset() {
  // A job still running belongs to the graph being forgotten: its result is dropped.
  if (optimizer_) optimizer_->wait();
  backend_ = std::make_unique<Backend>(config_, vocabulary_);
  backend_->setFullOptimizationDeferred(config_.full_optimization_in_background);
  backend_->setMemoryPressure(memory_pressure_);
  frames_ = KeyframeAnchoredTrajectory();
  keyframes_.clear();
  keyframe_bytes_.clear();
  latest_keyframe_id_ = -1;
  latest_keyframe_utime_ = 0;
  frames_seen_ = 0;
  stats_ = BackendStageStats();
  if (restored_) restore(restored_, fix_restored_keyframes_);
}

void BackendStage::restore(std::shared_ptr<const BackendSnapshot> snapshot,
                           bool fix_loaded_keyframes) {
  backend_->restore(*snapshot, fix_loaded_keyframes);
  restored_ = std::move(snapshot);
  fix_restored_keyframes_ = fix_loaded_keyframes;
  for (const KeyframePtr& keyframe : restored_->keyframes) {
    keyframes_.push_back(KeyframePoseEntry{keyframe->id, keyframe->utime, keyframe->segment,
                                           backend_->pose(keyframe->id)});
  }
  stats_.keyframes = static_cast<std::int64_t>(backend_->graph().numNodes());
}

std::optional<BackendCorrection> BackendStage::process(const EstimatedPacket& packet) {
  std::optional<BackendCorrection> correction;
  if (optimizer_) {
    // Heartbeats come here too, so a result is merged even while no frames arrive; the
    // correction then carries the newest keyframe's time.
    const Utime utime = packet.frame
                            ? packet.frame->utime
                            : (packet.odometry ? packet.odometry->utime : latest_keyframe_utime_);
    if (std::optional<FullOptimizationJob> done = optimizer_->poll()) {
      correction = mergeFullOptimization(*done, utime);
    }
  }
  // A keyframe's correction lists every pose too, so it supersedes a merge's.
  if (std::optional<BackendCorrection> from_keyframe = processKeyframe(packet)) {
    correction = std::move(from_keyframe);
  }
  if (optimizer_ && !optimizer_->busy()) {
    if (std::optional<FullOptimizationJob> job = backend_->takeFullOptimizationJob()) {
      optimizer_->submit(std::move(*job));
    }
  }
  return correction;
}

std::optional<BackendCorrection> BackendStage::processKeyframe(const EstimatedPacket& packet) {
  if (!packet.odometry) return std::nullopt;  // heartbeat
  const TrackingState state = packet.pose.tracking_state;
  if (state == TrackingState::kLost || state == TrackingState::kNotInitialized) {
    return std::nullopt;
  }
  const OdometryResult& odometry = *packet.odometry;
  const SE3& T_world_camera = packet.pose.T_world_camera;  // uncorrected (filter) world
  std::optional<BackendCorrection> correction;
  if (odometry.is_keyframe && odometry.keyframe) {
    // The graph takes the filter's pose: the published poses and the map are built from it.
    auto keyframe = compactKeyframe(
        *odometry.keyframe, config_.align_patches && memory_pressure_ == MemoryPressure::kNone);
    keyframe->T_world_camera = T_world_camera;
    // Measured straight against the previous keyframe: tracking's covariance of that step is the
    // odometry edge's uncertainty.
    const bool measured_from_previous_keyframe =
        latest_keyframe_id_ >= 0 && odometry.reference_keyframe_id == latest_keyframe_id_;
    const BackendUpdate update = measured_from_previous_keyframe
                                     ? backend_->addKeyframe(keyframe, odometry.covariance_ref_curr)
                                     : backend_->addKeyframe(keyframe);
    latest_keyframe_id_ = keyframe->id;
    latest_keyframe_utime_ = keyframe->utime;
    frames_.addKeyframe(keyframe);
    if (update.culled) {
      ++stats_.culled_keyframes;
    } else {
      keyframes_.push_back(
          KeyframePoseEntry{keyframe->id, keyframe->utime, keyframe->segment, T_world_camera});
      const auto bytes = static_cast<std::int64_t>(keyframeBytes(*keyframe));
      keyframe_bytes_[keyframe->id] = bytes;
      stats_.keyframe_bytes += bytes;
    }
    forgetCulledEarlierKeyframes(update.culled_earlier_ids);
    stats_.keyframes = static_cast<std::int64_t>(backend_->graph().numNodes());
    if (restored_ && stats_.frames_before_localization < 0 && backend_->newestKeyframeInMap()) {
      stats_.frames_before_localization = frames_seen_;
    }
    if (update.optimized) correction = makeCorrection(update, keyframe->utime);
  }
  frames_.addFrame(odometry, T_world_camera);
  ++frames_seen_;
  return correction;
}

void BackendStage::forgetCulledEarlierKeyframes(const std::vector<std::int64_t>& ids) {
  if (ids.empty()) return;
  stats_.culled_keyframes += static_cast<std::int64_t>(ids.size());
  for (const std::int64_t id : ids) {
    const auto bytes = keyframe_bytes_.find(id);
    if (bytes == keyframe_bytes_.end()) continue;
    stats_.keyframe_bytes -= bytes->second;
    keyframe_bytes_.erase(bytes);
  }
  const std::unordered_set<std::int64_t> culled(ids.begin(), ids.end());
  keyframes_.erase(std::remove_if(keyframes_.begin(), keyframes_.end(),
                                  [&culled](const KeyframePoseEntry& entry) {
                                    return culled.count(entry.keyframe_id) != 0;
                                  }),
                   keyframes_.end());
}

std::optional<BackendCorrection> BackendStage::mergeFullOptimization(const FullOptimizationJob& job,
                                                                     Utime utime) {
  const BackendUpdate update = backend_->finishFullOptimization(job);
  if (!update.optimized) {
    SLAMD_LOG_WARN(kLog) << "whole-graph optimisation failed ("
                         << optimizationStatusName(job.result.status)
                         << "): the graph keeps its local-window estimate";
    return std::nullopt;
  }
  ++stats_.background_optimizations;
  stats_.max_background_optimization_ms =
      std::max(stats_.max_background_optimization_ms, job.result.time_ms);
  SLAMD_LOG_DEBUG(kLog) << "whole graph of " << job.result.num_nodes << " keyframes optimised in "
                        << job.result.time_ms << " ms in the background, merged";
  return makeCorrection(update, utime);
}

void BackendStage::setMemoryPressure(MemoryPressure pressure) {
  memory_pressure_ = pressure;
  backend_->setMemoryPressure(pressure);
}

void BackendStage::finish() {
  if (!optimizer_) return;
  const Utime utime = latest_keyframe_utime_;
  if (std::optional<FullOptimizationJob> done = optimizer_->wait()) {
    mergeFullOptimization(*done, utime);
  }
  if (std::optional<FullOptimizationJob> job = backend_->takeFullOptimizationJob()) {
    job->run();
    mergeFullOptimization(*job, utime);
  }
}

BackendCorrection BackendStage::makeCorrection(const BackendUpdate& update, Utime utime) {
  ++stats_.optimizations;
  stats_.loops = backend_->numLoops();
  stats_.local_edges = backend_->numLocalEdges();
  stats_.relocalizations = backend_->numRelocalizations();
  // A whole-graph optimisation merged from the background took no time in this thread.
  const bool in_background = optimizer_ != nullptr && update.full_optimization;
  stats_.last_optimization_ms = in_background ? 0.0 : update.optimization.time_ms;
  stats_.max_optimization_ms = std::max(stats_.max_optimization_ms, stats_.last_optimization_ms);

  BackendCorrection correction;
  correction.T_world_uncorrected = update.T_world_odometry;
  correction.keyframe_poses = update.corrected_poses;
  correction.relocalized = update.relocalized;
  correction.map_frame_known = backend_->newestKeyframeInMap();
  correction.newest_segment = backend_->newestKeyframeSegment();
  KeyframeTrajectory& trajectory = correction.trajectory;
  trajectory.utime = utime;
  trajectory.sequence = sequence_++;
  trajectory.T_world_uncorrected = update.T_world_odometry;
  trajectory.num_loops = backend_->numLoops();
  trajectory.num_relocalizations = static_cast<int>(stats_.relocalizations);
  trajectory.optimization_ms = update.optimization.time_ms;
  trajectory.keyframes = keyframes_;
  for (KeyframePoseEntry& entry : trajectory.keyframes) {
    entry.T_world_camera = backend_->pose(entry.keyframe_id);
  }
  if (update.relocalized) {
    SLAMD_LOG_INFO(kLog) << "keyframe " << update.keyframe_id << ": relocalised against keyframe "
                         << update.relocalization.match_id << " after "
                         << update.relocalization_attempts
                         << " attempts: tracking resumes in the same map";
  }
  if (update.loop.status == LoopStatus::kLoopFound) {
    SLAMD_LOG_INFO(kLog) << "keyframe " << update.keyframe_id << ": loop closed with keyframe "
                         << update.loop.match_id << " (" << update.loop.num_inliers << " inliers)";
  }
  SLAMD_LOG_DEBUG(kLog) << "keyframe " << update.keyframe_id << ": " << update.num_local_edges
                        << " local edges; graph of " << update.optimization.num_nodes
                        << " keyframes, " << update.optimization.num_edges << " edges optimised in "
                        << update.optimization.time_ms << " ms";
  return correction;
}

Trajectory BackendStage::optimizedTrajectory() const { return frames_.corrected(*backend_); }

}  // namespace slamd
