#include "slamd/app/stage_steps.hpp"

#include <algorithm>
#include <stdexcept>
#include <unordered_set>

#include "slamd/common/log.hpp"

namespace slamd {

namespace {
constexpr const char* kLog = "slamd";

/// When a periodic walk of the whole map that started at start_ns and took walk_ns may run
/// again: after period_ns, and never more often than keeps the walks at 1% of the mapping
/// thread's time (tens of milliseconds for millions of voxels), so that they never set its p99.
std::int64_t nextWalkNs(std::int64_t start_ns, std::int64_t walk_ns, std::int64_t period_ns) {
  return start_ns + std::max<std::int64_t>(period_ns, 100 * walk_ns);
}

/// The keyframes of `kept` a correction culled. A correction lists every keyframe the back end
/// holds up to its newest (ids increase): a keyframe older than that and not listed was culled
/// by the back end (or never taken), and no correction will ever move it again.
std::vector<std::int64_t> culledKeyframes(
    const std::vector<std::pair<std::int64_t, SE3>>& keyframe_poses,
    const std::vector<std::int64_t>& kept) {
  std::int64_t newest_id = -1;
  std::unordered_set<std::int64_t> listed;
  for (const auto& entry : keyframe_poses) {
    newest_id = std::max(newest_id, entry.first);
    listed.insert(entry.first);
  }
  std::vector<std::int64_t> culled;
  for (const std::int64_t id : kept) {
    if (id < newest_id && listed.count(id) == 0) culled.push_back(id);
  }
  return culled;
}

planes::PlaneMapParams planeMapParams(const MappingConfig& config) {
  planes::PlaneMapParams params;
  params.max_angle_deg = config.planes_max_angle_deg;
  params.max_distance_m = config.planes_max_distance_m;
  params.max_gap_m = config.planes_max_gap_m;
  return params;
}
}  // namespace

bool StepBase::enter(std::uint64_t epoch, const RgbdFramePtr& frame) {
  return enter(epoch, frame ? frame->utime : Utime{-1});
}

bool StepBase::enter(std::uint64_t epoch, Utime utime) {
  if (epoch < epoch_) {
    ++stale_;
    return false;
  }
  if (epoch > epoch_) {
    reset();
    epoch_ = epoch;
    ++resets_;
  }
  if (trace_) trace_(StepTraceEntry{utime, epoch, resets_});
  return true;
}

// --- capture ---------------------------------------------------------------------------------

CaptureStep::CaptureStep(FrameSource& source, std::int64_t heartbeat_period_ns,
                         std::function<void(const RgbdFrame&)> republish)
    : source_(source),
      live_(source.isLive()),
      heartbeat_period_ns_(heartbeat_period_ns),
      republish_(std::move(republish)),
      last_emit_ns_(steadyNowNs()) {}

void CaptureStep::resume() {
  paused_.store(false, std::memory_order_release);
  resume_signal_.notify();
}

CaptureStepStats CaptureStep::stats() const {
  return CaptureStepStats{frames_dropped_paused_.load(std::memory_order_relaxed),
                          reset_epoch_.load(std::memory_order_acquire)};
}

SourceStep<CapturePacket> CaptureStep::emit(RgbdFramePtr frame) {
  last_emit_ns_ = steadyNowNs();
  return SourceStep<CapturePacket>::of(
      CapturePacket{std::move(frame), reset_epoch_.load(std::memory_order_acquire)});
}

SourceStep<CapturePacket> CaptureStep::process() {
  if (paused() && !live_) {
    // A recording simply waits; a live source keeps being read (below) so that resuming
    // continues from the present, not from a stale buffered frame.
    const auto seen = resume_signal_.epoch();
    if (paused() && steadyNowNs() - last_emit_ns_ < heartbeat_period_ns_) {
      resume_signal_.waitFor(
          seen, std::chrono::steady_clock::now() + std::chrono::nanoseconds(heartbeat_period_ns_));
      return SourceStep<CapturePacket>::idle();
    }
    return emit(nullptr);
  }
  FrameRead read = source_.next(std::chrono::milliseconds(100));
  if (read.status == FrameRead::Status::kEndOfStream) return SourceStep<CapturePacket>::end();
  if (read.status == FrameRead::Status::kFrame && paused()) {
    frames_dropped_paused_.fetch_add(1, std::memory_order_relaxed);
  } else if (read.status == FrameRead::Status::kFrame) {
    auto frame = std::make_shared<RgbdFrame>(*read.frame);  // shallow: images are shared
    if (frame->received_steady_ns == 0) frame->received_steady_ns = steadyNowNs();
    ensureGray(*frame);
    if (republish_) republish_(*frame);
    return emit(std::move(frame));
  }
  if (steadyNowNs() - last_emit_ns_ >= heartbeat_period_ns_) return emit(nullptr);
  return SourceStep<CapturePacket>::idle();
}

// --- tracking --------------------------------------------------------------------------------

std::optional<TrackedPacket> TrackingStep::process(CapturePacket packet) {
  if (!enter(packet.reset_epoch, packet.frame)) return std::nullopt;
  TrackedPacket out;
  out.frame = std::move(packet.frame);
  out.reset_epoch = packet.reset_epoch;
  map_keyframes_.take(resetEpoch(), [this](MapKeyframesPacket&& near) {
    odometry_.setMapKeyframes(std::move(near.keyframes));
  });
  if (out.frame) {
    out.odometry = odometry_.processFrame(out.frame);
    if (out.odometry->stats.used_map_keyframe) {
      map_keyframe_reuses_.fetch_add(1, std::memory_order_relaxed);
    }
    if (out.odometry->stats.relocalization_keyframe) {
      relocalization_keyframes_.fetch_add(1, std::memory_order_relaxed);
    }
    tracking_state_.store(static_cast<int>(out.odometry->tracking_state),
                          std::memory_order_relaxed);
    implausible_estimates_.fetch_add(
        static_cast<std::uint64_t>(out.odometry->stats.implausible_estimates),
        std::memory_order_relaxed);
    prior_disagreements_.fetch_add(
        static_cast<std::uint64_t>(out.odometry->stats.prior_disagreements),
        std::memory_order_relaxed);
    if (out.odometry->stats.used_dense_alignment) {
      dense_aligned_frames_.fetch_add(1, std::memory_order_relaxed);
    }
  }
  return out;
}

// --- vanishing points ------------------------------------------------------------------------

void VanishingPointStep::process(CapturePacket packet) {
  if (!enter(packet.reset_epoch, packet.frame) || !packet.frame) return;
  if (!detector_) detector_.emplace(config_, packet.frame->intrinsics);
  channel_.push(VanishingPointPacket{packet.frame->utime, detector_->detect(packet.frame->gray)});
}

// --- plane segmentation ----------------------------------------------------------------------

void PlaneSegmentationStep::process(CapturePacket packet) {
  if (!enter(packet.reset_epoch, packet.frame) || !packet.frame) return;
  PlaneSegmentationPacket out;
  out.utime = packet.frame->utime;
  if (channel_.corridor_mode.load(std::memory_order_relaxed)) {
    try {
      auto planes = std::make_shared<planes::PlaneSegmentation>(segmenter_.segment(*packet.frame));
      planes->labels = planes->labels.clone();  // the segmenter reuses its buffer
      out.planes = std::move(planes);
    } catch (...) {
      // A frame the segmenter refuses (wrong sizes or types): the filter still gets its packet,
      // unsegmented; the pipeline counts the error.
      channel_.push(std::move(out));
      throw;
    }
  }
  channel_.push(std::move(out));
}

// --- filter ----------------------------------------------------------------------------------

FilterStep::FilterStep(const FilterConfig& config, VanishingPointChannel* vanishing_points,
                       std::chrono::microseconds result_wait,
                       PlaneSegmentationChannel* plane_segmentation)
    : estimator_(config, vanishing_points ? VanishingPointSource::kPrecomputed
                                          : VanishingPointSource::kDetectHere),
      vanishing_points_(vanishing_points, result_wait),
      plane_segmentation_(plane_segmentation, result_wait),
      plane_channel_(plane_segmentation) {}

std::optional<EstimatedPacket> FilterStep::process(TrackedPacket packet) {
  if (!enter(packet.reset_epoch, packet.frame)) return std::nullopt;
  if (vanishing_points_.connected() && packet.frame) {
    std::optional<VanishingPointPacket> result = vanishing_points_.take(packet.frame->utime);
    if (result) packet.vanishing_point = std::move(result->detection);
  }
  if (plane_segmentation_.connected() && packet.frame) {
    packet.plane_segmentation = plane_segmentation_.take(packet.frame->utime);
  }
  EstimatedPacket out = estimator_.process(std::move(packet));
  if (plane_channel_) {
    plane_channel_->corridor_mode.store(estimator_.corridorModeOn(), std::memory_order_relaxed);
  }
  return out;
}

// --- publish ---------------------------------------------------------------------------------

void TrackingTally::record(TrackingState state, Utime utime) {
  last_state = state;
  latest_utime.store(utime, std::memory_order_relaxed);
  const bool measured = state == TrackingState::kOk || state == TrackingState::kRelocalized;
  const double since_previous_s =
      previous_utime >= 0 ? utimeToSeconds(utime - previous_utime) : 0.0;
  if (since_previous_s > kCaptureGapS) {
    ++capture_gaps;
    longest_capture_gap_s = std::max(longest_capture_gap_s, since_previous_s);
    gap_return_utime = utime;
  }
  previous_utime = utime;
  if (gap_return_utime >= 0 && measured) {
    longest_resume_s = std::max(longest_resume_s, utimeToSeconds(utime - gap_return_utime));
    gap_return_utime = -1;
  }
  const bool losing = state == TrackingState::kPredicted || state == TrackingState::kLost;
  (measured                             ? tracked
   : state == TrackingState::kPredicted ? predicted
   : state == TrackingState::kLost      ? lost
                                        : not_initialized)
      .fetch_add(1, std::memory_order_relaxed);
  const Utime start = loss_start_utime.load(std::memory_order_relaxed);
  if (losing) {
    if (start < 0) loss_start_utime.store(utime, std::memory_order_relaxed);
    loss_frames.fetch_add(1, std::memory_order_relaxed);
    longest_loss_s = std::max(longest_loss_s, start < 0 ? 0.0 : utimeToSeconds(utime - start));
  } else if (start >= 0) {
    // The loss lasted until this frame, the first measured again (or a reset).
    longest_loss_s = std::max(longest_loss_s, utimeToSeconds(utime - start));
    loss_start_utime.store(-1, std::memory_order_relaxed);
    loss_frames.store(0, std::memory_order_relaxed);
  }
}

std::string TrackingTally::lossNote() const {
  const Utime start = loss_start_utime.load(std::memory_order_relaxed);
  if (start < 0) return {};
  std::ostringstream out;
  out.precision(2);
  out << std::fixed << "tracking lost for "
      << utimeToSeconds(latest_utime.load(std::memory_order_relaxed) - start) << " s ("
      << loss_frames.load(std::memory_order_relaxed) << " frames)";
  return out.str();
}

PublishStep::PublishStep(DaemonPublisher& publisher, std::string world_frame,
                         std::string camera_frame, SpscQueue<PoseCorrection>* corrections)
    : publisher_(publisher),
      world_frame_(std::move(world_frame)),
      camera_frame_(std::move(camera_frame)),
      corrections_(corrections),
      with_back_end_(corrections != nullptr) {}

void PublishStep::reset() {
  correction_ = SE3::Identity();
  corrected_ = false;
  awaiting_map_frame_ = localizes_in_loaded_map_;
  current_segment_ = -1;
  newest_segment_in_map_ = -1;
}

void PublishStep::awaitMapFrame() {
  localizes_in_loaded_map_ = true;
  awaiting_map_frame_ = true;
}

void PublishStep::process(EstimatedPacket packet) {
  if (!enter(packet.reset_epoch, packet.frame)) return;
  corrections_.take(resetEpoch(), [this](PoseCorrection correction) {
    correction_ = correction.T_world_uncorrected;
    relocalized_ = relocalized_ || correction.relocalized;
    if (correction.map_frame_known) {
      newest_segment_in_map_ = std::max(newest_segment_in_map_, correction.segment);
    }
    corrected_ = true;
  });
  if (!packet.frame || !packet.odometry) return;
  if (with_back_end_) {
    // The run's first segment defines the map's frame, unless a loaded session's map does.
    if (current_segment_ < 0 && !localizes_in_loaded_map_) {
      newest_segment_in_map_ = packet.odometry->segment;
    }
    current_segment_ = packet.odometry->segment;
    awaiting_map_frame_ = current_segment_ > newest_segment_in_map_;
  }
  PoseEstimate pose = packet.pose;
  if (corrected_) {
    pose = transformedPose(pose, correction_);
    pose.source = PoseSource::kOptimized;
  }
  if (relocalized_ && pose.tracking_state == TrackingState::kOk) {
    pose.tracking_state = TrackingState::kRelocalized;
    relocalized_ = false;
  }
  pose.parent_frame = world_frame_;
  pose.child_frame = camera_frame_;
  tally_.record(pose.tracking_state, pose.utime);
  tally_.awaiting_map_frame.store(awaiting_map_frame_, std::memory_order_relaxed);
  // Not yet in the map's frame: said on every pose that has one (a lost pose says lost).
  if (awaiting_map_frame_ && pose.tracking_state != TrackingState::kLost &&
      pose.tracking_state != TrackingState::kNotInitialized) {
    pose.tracking_state = TrackingState::kNotLocalized;
    tally_.not_localized.fetch_add(1, std::memory_order_relaxed);
  }
  publisher_.publishPose(pose);
  end_to_end_.recordNs(steadyNowNs() - packet.frame->received_steady_ns);
  publisher_.publishOdometry(*packet.odometry);
  if (packet.vanishing_point) publisher_.publishVanishingPoint(pose.utime, *packet.vanishing_point);
  // A lost pose, or the placeholder before tracking could start, is not an estimate.
  if (pose.tracking_state != TrackingState::kLost &&
      pose.tracking_state != TrackingState::kNotInitialized &&
      pose.tracking_state != TrackingState::kNotLocalized) {
    trajectory_.push_back(StampedPose{utimeToSeconds(pose.utime), pose.T_world_camera});
  }
}

// --- mapping ---------------------------------------------------------------------------------

MappingStep::MappingStep(Mapper& mapper, const MappingConfig& config, DaemonPublisher& publisher,
                         SpscQueue<MapCorrection>* corrections, SpscQueue<MapRequest>* requests)
    : mapper_(mapper),
      keyframes_only_(config.keyframes_only),
      frame_id_(config.frame_id),
      planes_enabled_(config.planes_enabled),
      snap_depth_(config.planes_snap_depth),
      snap_sigmas_(config.planes_snap_sigmas),
      plane_map_(planeMapParams(config)),
      step_budget_s_(config.keyframe_step_budget_ms * 1e-3),
      publisher_(publisher),
      corrections_(corrections),
      requests_(requests) {}

void MappingStep::reset() {
  mapper_.reset();
  plane_map_.clear();
  plane_map_changed_ = true;
  T_world_uncorrected_ = SE3::Identity();
  if (loaded_map_path_.empty()) return;
  // The back end restores the loaded session: the map it was saved with comes back too.
  awaiting_map_frame_ = true;
  const MapFileResult loaded = mapper_.loadMap(loaded_map_path_);
  if (!loaded.ok) {
    SLAMD_LOG_WARN(kLog) << "RESET: the loaded session's map could not be read again ("
                         << loaded.error << "); the map starts empty";
    return;
  }
  std::vector<KeyframeCloudRecord> clouds;
  std::string error;
  if (!loaded_clouds_path_.empty() &&
      !readKeyframeCloudRecords(loaded_clouds_path_, clouds, &error)) {
    SLAMD_LOG_WARN(kLog) << "RESET: the loaded session's keyframe clouds could not be read again ("
                         << error << "); its map cannot follow corrections";
    return;
  }
  mapper_.restoreKeyframeClouds(std::move(clouds));
}

void MappingStep::useLoadedMap(bool frozen, std::string map_path, std::string clouds_path) {
  map_frozen_ = frozen;
  awaiting_map_frame_ = true;
  loaded_map_path_ = std::move(map_path);
  loaded_clouds_path_ = std::move(clouds_path);
}

MappingStepStats MappingStep::stats() const {
  return MappingStepStats{leaf_voxels_.load(std::memory_order_relaxed),
                          occupied_voxels_.load(std::memory_order_relaxed),
                          keyframes_segmented_.load(std::memory_order_relaxed),
                          pixels_snapped_.load(std::memory_order_relaxed),
                          catch_up_cycles_deferred_.load(std::memory_order_relaxed)};
}

void MappingStep::applyCorrections() {
  std::optional<BackendCorrection> newest;
  corrections_.take(resetEpoch(),
                    [&newest](MapCorrection item) { newest = std::move(item.correction); });
  if (newest) {
    if (newest->map_frame_known) awaiting_map_frame_ = false;
    forgetCulledKeyframes(newest->keyframe_poses);
    T_world_uncorrected_ = newest->T_world_uncorrected;
    const KeyframeCorrectionResult corrected = mapper_.correctKeyframePoses(newest->keyframe_poses);
    if (plane_map_.setKeyframePoses(newest->keyframe_poses) > 0) plane_map_changed_ = true;
    if (corrected.keyframes_to_move > 0) {
      SLAMD_LOG_DEBUG(kLog) << "correction: " << corrected.keyframes_to_move
                            << " keyframes to move in the map";
    }
  }
}

void MappingStep::catchUp(std::int64_t cycle_start_ns, bool keyframe_mapped) {
  // New keyframes go in and keyframes a correction moved move a part at a time, in what is left
  // of this frame's budget, so that this stage's time per frame stays bounded however large the
  // map and the correction are.
  if (mapper_.keyframesQueued() == 0) {
    deferred_last_cycle_ = false;
    return;
  }
  const double left_s = step_budget_s_ - 1e-9 * static_cast<double>(steadyNowNs() - cycle_start_ns);
  // A cycle that mapped a keyframe (its planes and cloud), or whose own work (an update, a voxel
  // count) has left no room for a step like the last, leaves the steps to the next frames, most
  // of which map nothing. But the map must follow on a machine too loaded for any cycle to fit
  // the budget: a cycle after one that left waiting steps undone takes a step anyway, so the
  // map moves at least a step every other frame.
  const bool no_room = keyframe_mapped || left_s < mapper_.lastStepSeconds();
  if (no_room && !deferred_last_cycle_) {
    deferred_last_cycle_ = true;
    catch_up_cycles_deferred_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  deferred_last_cycle_ = false;
  constexpr double kOneStepBudgetS = 1e-9;
  const CatchUpResult moved = mapper_.catchUp(std::max(left_s, kOneStepBudgetS));
  if (moved.caught_up) {
    SLAMD_LOG_DEBUG(kLog) << "map caught up with the corrections ("
                          << mapper_.stats().keyframes_moved << " keyframe moves so far)";
  }
}

void MappingStep::forgetCulledKeyframes(
    const std::vector<std::pair<std::int64_t, SE3>>& keyframe_poses) {
  for (const std::int64_t id : culledKeyframes(keyframe_poses, mapper_.keptKeyframeIds())) {
    mapper_.forgetKeyframeInSteps(id);
  }
  for (const std::int64_t id : culledKeyframes(keyframe_poses, plane_map_.keyframeIds())) {
    plane_map_.forgetKeyframe(id);
    plane_map_changed_ = true;
  }
}

const RgbdFrame& MappingStep::addKeyframePlanes(const RgbdFrame& frame, const SE3& T_world_camera,
                                                std::int64_t keyframe_id) {
  const planes::PlaneSegmentation& segmentation = segmenter_.segment(frame);
  plane_map_.addKeyframe(keyframe_id, T_world_camera, segmentation.planes, frame.utime);
  plane_map_changed_ = true;
  keyframes_segmented_.fetch_add(1, std::memory_order_relaxed);
  if (!snap_depth_) return frame;
  const planes::DepthSnapStats snapped = planes::snapDepthToPlanes(
      frame.depth_m, segmentation, frame.intrinsics, snap_sigmas_, snapped_depth_m_);
  pixels_snapped_.fetch_add(snapped.snapped, std::memory_order_relaxed);
  // The images are shared, not copied; only the depth differs.
  snapped_frame_ = frame;
  snapped_frame_.depth_m = snapped_depth_m_;
  return snapped_frame_;
}

void MappingStep::publishPlaneMap() {
  if (!planes_enabled_) return;
  publisher_.publishPlaneMap(plane_map_.snapshot(frame_id_));
  plane_map_changed_ = false;
}

MapFileResult MappingStep::savePlaneMap(const std::string& map_path) {
  MapFileResult result;
  result.path = planes::planesPlyPathFor(map_path);
  if (!planes_enabled_) {
    result.error = "the plane map is off (mapping.planes.enabled)";
    return result;
  }
  const std::int64_t start_ns = steadyNowNs();
  result.ok = planes::writePlaneMapPly(result.path, plane_map_.snapshot(frame_id_), &result.error);
  result.seconds = 1e-9 * static_cast<double>(steadyNowNs() - start_ns);
  return result;
}

SavedMap saveMapForSession(Mapper& mapper, const std::string& map_path,
                           const std::string& clouds_path) {
  SavedMap saved;
  saved.file = mapper.saveMap(map_path);
  if (!saved.file.ok) return saved;
  const std::vector<KeyframeCloudRecord> clouds = mapper.keyframeCloudRecords();
  if (!clouds.empty()) {
    saved.clouds_written = writeKeyframeCloudRecords(clouds_path, clouds, &saved.clouds_error);
  }
  const auto describe = [&saved](const auto& tree) {
    saved.voxels = static_cast<std::int64_t>(tree.getNumLeafNodes());
    if (tree.size() == 0) return;
    tree.getMetricMin(saved.min_m.x(), saved.min_m.y(), saved.min_m.z());
    tree.getMetricMax(saved.max_m.x(), saved.max_m.y(), saved.max_m.z());
  };
  if (const octomap::OcTree* tree = mapper.ocTree()) describe(*tree);
  if (const octomap::ColorOcTree* tree = mapper.colorOcTree()) describe(*tree);
  return saved;
}

void MappingStep::serveRequests() {
  if (requests_ == nullptr) return;
  while (auto request = requests_->tryPop()) {
    if (request->kind == MapRequest::Kind::kPublish) {
      publisher_.publishFullMap(mapper_.fullMap());
      publishPlaneMap();
      continue;
    }
    if (request->saved) {
      request->saved->set_value(saveMapForSession(mapper_, request->path, request->clouds_path));
      continue;
    }
    const MapFileResult saved = mapper_.saveMap(request->path);
    if (saved.ok) {
      SLAMD_LOG_INFO(kLog) << "SAVE_MAP: map written to " << saved.path;
    } else {
      SLAMD_LOG_ERROR(kLog) << "SAVE_MAP failed: " << saved.error;
    }
    if (!planes_enabled_) continue;
    const MapFileResult planes_saved = savePlaneMap(request->path);
    if (planes_saved.ok) {
      SLAMD_LOG_INFO(kLog) << "SAVE_MAP: " << plane_map_.worldPlanes().size()
                           << " planes written to " << planes_saved.path;
    } else {
      SLAMD_LOG_ERROR(kLog) << "SAVE_MAP: planes not written: " << planes_saved.error;
    }
  }
}

void MappingStep::publishOutputs(const MapperOutputs& outputs) {
  if (outputs.update && !outputs.update->voxels.empty()) {
    publisher_.publishMapUpdate(*outputs.update);
  }
  if (outputs.full_map) publisher_.publishFullMap(*outputs.full_map);
  // The planes go out at the voxel map's cadence: with an update when they changed, and with
  // every full map, so that a subscriber that missed one has them again within a period.
  if (outputs.full_map || (outputs.update && plane_map_changed_)) publishPlaneMap();
  if (outputs.snapshot) {
    // Logged on each change between failing and succeeding, so a full disk gives one line per
    // retry and one when it recovers, not one per period forever.
    if (!outputs.snapshot->ok) {
      SLAMD_LOG_WARN(kLog) << "map snapshot failed (kept in memory, the previous snapshot is "
                              "intact; retrying): "
                           << outputs.snapshot->error;
    } else if (snapshot_failing_) {
      SLAMD_LOG_INFO(kLog) << "map snapshot written again: " << outputs.snapshot->path;
    }
    snapshot_failing_ = !outputs.snapshot->ok;
  }
}

void MappingStep::process(const EstimatedPacket& packet) {
  if (!enter(packet.reset_epoch, packet.frame)) return;
  const std::int64_t cycle_start_ns = steadyNowNs();
  if (memory_pressure_ != nullptr) {
    const MemoryPressure pressure = memory_pressure_->load(std::memory_order_relaxed);
    mapper_.setMemoryPressure(pressure);
    if (pressure == MemoryPressure::kOver) mapper_.releaseKeyframeClouds(kKeptCloudsOverTheLimit);
  }
  applyCorrections();
  serveRequests();
  std::optional<std::int64_t> keyframe_id;
  if (packet.odometry && packet.odometry->is_keyframe && packet.odometry->keyframe) {
    keyframe_id = packet.odometry->keyframe->id;
  }
  // Before the run is localised in a loaded map only keyframes are kept, held out of the map
  // until a correction gives them poses in its frame (the back end may place this run long
  // after tracking made them).
  const bool mapped = !map_frozen_ && (!awaiting_map_frame_ || keyframe_id.has_value());
  bool keyframe_mapped = false;
  if (mapped && packet.frame && packet.odometry &&
      packet.pose.tracking_state != TrackingState::kLost &&
      packet.pose.tracking_state != TrackingState::kNotInitialized &&
      (!keyframes_only_ || packet.odometry->is_keyframe)) {
    const SE3 T_world_camera = T_world_uncorrected_ * packet.pose.T_world_camera;
    // A keyframe goes into the queue (kept, it goes in a part at a time, see catchUp); other
    // frames go in at once.
    // Planes: keyframes only (about one a second, 4 ms each to segment).
    const RgbdFrame& frame = keyframe_id && planes_enabled_
                                 ? addKeyframePlanes(*packet.frame, T_world_camera, *keyframe_id)
                                 : *packet.frame;
    const IntegrationResult result =
        awaiting_map_frame_ ? mapper_.holdKeyframe(frame, T_world_camera, *keyframe_id)
        : keyframe_id       ? mapper_.addKeyframe(frame, T_world_camera, *keyframe_id)
                            : mapper_.integrate(frame, T_world_camera);
    if (result.status == IntegrationStatus::kBadFrame ||
        result.status == IntegrationStatus::kBadPose) {
      // The pipeline counts a thrown error against this stage and carries on.
      throw std::runtime_error("frame not mapped: " + result.error);
    }
    coarsenFarMap(T_world_camera);
    keyframe_mapped = keyframe_id.has_value();
  }
  // A keyframe's planes and cloud are its cycle's work. The update and the voxel count wait for
  // the next frame's cycle (most map nothing), so that one cycle does not stack them: the
  // keyframes' cycles are the ones that set this stage's p99.
  if (!keyframe_mapped) {
    publishOutputs(mapper_.poll(mapper_.latestUtime()));
    // Counting voxels walks the whole tree (tens of ms for a corridor's map): every few seconds
    // is plenty for the status channel, and keeps these cycles out of the stage's p99.
    if (const std::int64_t now_ns = steadyNowNs(); now_ns >= next_voxel_count_ns_) {
      const VoxelCounts counts = mapper_.countVoxels();
      leaf_voxels_.store(static_cast<std::int64_t>(counts.leaves), std::memory_order_relaxed);
      occupied_voxels_.store(static_cast<std::int64_t>(counts.occupied), std::memory_order_relaxed);
      next_voxel_count_ns_ = nextWalkNs(now_ns, steadyNowNs() - now_ns, kVoxelCountPeriodNs);
    }
  }
  // Last, in what the frame's budget has left after everything else this cycle did (a full map,
  // a voxel count, a coarsening), so that those walks do not come on top of a whole budget's
  // steps: the cycle's time stays near the budget. Its changes go out with the next update.
  if (!awaiting_map_frame_) catchUp(cycle_start_ns, keyframe_mapped);
}

void MappingStep::coarsenFarMap(const SE3& T_world_camera) {
  if (memory_pressure_ == nullptr ||
      memory_pressure_->load(std::memory_order_relaxed) != MemoryPressure::kOver) {
    return;
  }
  const std::int64_t now_ns = steadyNowNs();
  if (now_ns < next_coarsening_ns_) return;
  const CoarsenResult result = mapper_.coarsenFarMap(T_world_camera.translation());
  next_coarsening_ns_ =
      nextWalkNs(now_ns, static_cast<std::int64_t>(result.seconds * 1e9), kCoarseningPeriodNs);
  if (result.blocks_merged > 0) {
    SLAMD_LOG_INFO(kLog) << "memory over the limit: the map beyond "
                         << mapper_.config().coarse_far_radius_m
                         << " m of the camera made coarser: " << result.blocks_merged
                         << " blocks merged, " << result.nodes_removed << " nodes freed in "
                         << 1e3 * result.seconds << " ms";
  }
}

// --- back end --------------------------------------------------------------------------------

BackendStep::BackendStep(BackendStage& backend, std::string world_frame, DaemonPublisher& publisher,
                         SpscQueue<PoseCorrection>* pose_corrections,
                         SpscQueue<MapCorrection>* map_corrections,
                         SpscQueue<MapKeyframesPacket>* map_keyframes)
    : backend_(backend),
      world_frame_(std::move(world_frame)),
      publisher_(publisher),
      pose_corrections_(pose_corrections),
      map_corrections_(map_corrections),
      map_keyframes_(map_keyframes) {}

BackendStepStats BackendStep::stats() const {
  return BackendStepStats{keyframes_.load(std::memory_order_relaxed),
                          loops_.load(std::memory_order_relaxed),
                          relocalizations_.load(std::memory_order_relaxed)};
}

void BackendStep::process(const EstimatedPacket& packet) {
  // The back end's queue drops the images of frames that are not keyframes (see
  // slamBackendItem), so the capture time comes from the odometry.
  const Utime utime =
      packet.frame ? packet.frame->utime : (packet.odometry ? packet.odometry->utime : Utime{-1});
  if (!enter(packet.reset_epoch, utime)) return;
  if (memory_pressure_ != nullptr) {
    backend_.setMemoryPressure(memory_pressure_->load(std::memory_order_relaxed));
  }
  if (snapshot_requests_ != nullptr) {
    while (std::optional<SnapshotRequest> request = snapshot_requests_->tryPop()) {
      (*request)->set_value(std::make_shared<const BackendSnapshot>(backend_.backend().snapshot()));
    }
  }
  std::optional<BackendCorrection> correction = backend_.process(packet);
  const BackendStageStats& stats = backend_.stats();
  keyframes_.store(static_cast<std::int32_t>(stats.keyframes), std::memory_order_relaxed);
  loops_.store(static_cast<std::int32_t>(stats.loops), std::memory_order_relaxed);
  relocalizations_.store(static_cast<std::int32_t>(stats.relocalizations),
                         std::memory_order_relaxed);
  const std::int64_t newest_id = backend_.latestKeyframeId();
  if (map_keyframes_ != nullptr && newest_id >= 0 && newest_id != map_keyframes_anchor_id_) {
    map_keyframes_anchor_id_ = newest_id;
    // Tracking takes them on every frame; should the queue be full, the set is dropped and the
    // next keyframe's replaces it.
    const bool queued = map_keyframes_->tryPush(
        MapKeyframesPacket{backend_.backend().keyframesNear(newest_id), resetEpoch()});
    if (!queued) SLAMD_LOG_DEBUG(kLog) << "map keyframes not handed to tracking: queue full";
  }
  if (!correction) return;
  correction->trajectory.frame_id = world_frame_;
  publisher_.publishKeyframes(correction->trajectory);
  if (pose_corrections_ &&
      !pose_corrections_->tryPush(
          PoseCorrection{correction->T_world_uncorrected, correction->relocalized,
                         correction->map_frame_known, resetEpoch(), correction->newest_segment})) {
    // Cannot happen while the publish step keeps up (it drains on every frame); if it does,
    // the next correction replaces this one anyway.
    SLAMD_LOG_WARN(kLog) << "pose correction not handed to the publish step: queue full";
  }
  if (map_corrections_ &&
      !map_corrections_->tryPush(MapCorrection{std::move(*correction), resetEpoch()})) {
    SLAMD_LOG_WARN(kLog) << "map correction not handed to the mapping step: queue full";
  }
}

}  // namespace slamd
