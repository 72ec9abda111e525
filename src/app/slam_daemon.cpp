#include "slamd/app/slam_daemon.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <unordered_map>

#include <opencv2/core.hpp>

#include "slamd/app/backend_stage.hpp"
#include "slamd/app/command_save_path.hpp"
#include "slamd/app/daemon_config.hpp"
#include "slamd/comms/odometry_codec.hpp"
#include "slamd/app/pose_estimator.hpp"
#include "slamd/command_t.hpp"
#include "slamd/common/file_io.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/frame_codec.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/lcm_frame_publisher.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/comms/status_codec.hpp"
#include "slamd/eval/json_writer.hpp"
#include "slamd/pipeline/pipeline.hpp"
#include "slamd/mapping/mapper.hpp"
#include "slamd/sources/create_frame_source.hpp"

namespace slamd {

namespace {
constexpr const char* kLog = "slamd";
constexpr std::size_t kCommandQueueCapacity = 64;

/// A request from the control loop to the mapping thread, which owns the map.
struct MapRequest {
  enum class Kind { kSave, kPublish };
  Kind kind = Kind::kSave;
  std::string path;  ///< kSave: .bt or .ot
};

/// The back end's correction as the publish thread needs it.
struct PoseCorrection {
  SE3 T_world_uncorrected = SE3::Identity();
  bool relocalized = false;  ///< mark the next published pose TRACKING_RELOCALIZED
};

/// What the mapping thread keeps between frames.
struct MappingThreadState {
  std::uint64_t reset_seen = 0;
  std::int64_t next_occupancy_count_ns = 0;
  /// The back end's correction: uncorrected (filter) world -> corrected world.
  SE3 T_world_uncorrected = SE3::Identity();
  /// Pose each kept keyframe cloud is in the map at (corrected world).
  std::unordered_map<std::int64_t, SE3> keyframe_map_poses;
};

/// Published poses by tracking state, and the current loss. Written by the publish thread; the
/// atomics are read by the control thread for the status note, the rest after the publish thread
/// has been joined.
struct TrackingTally {
  std::atomic<std::uint64_t> tracked{0};  ///< measured: OK or RELOCALIZED
  std::atomic<std::uint64_t> predicted{0};
  std::atomic<std::uint64_t> lost{0};
  std::atomic<std::uint64_t> not_initialized{0};
  /// Frame time of the first pose of the current loss (predicted or lost), -1 while tracking.
  std::atomic<Utime> loss_start_utime{-1};
  std::atomic<Utime> latest_utime{0};
  std::atomic<std::uint64_t> loss_frames{0};  ///< poses in the current loss
  double longest_loss_s = 0.0;
  TrackingState last_state = TrackingState::kNotInitialized;
  // Capture gaps (a camera that stopped delivering and came back): frames more than
  // kCaptureGapS apart in capture time, and how long after the first frame back tracking
  // measured a pose again.
  static constexpr double kCaptureGapS = 0.5;
  std::uint64_t capture_gaps = 0;
  double longest_capture_gap_s = 0.0;
  double longest_resume_s = 0.0;
  Utime previous_utime = -1;
  Utime gap_return_utime = -1;  ///< first frame after a gap, until a pose is measured

  void record(TrackingState state, Utime utime) {
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
    (measured                               ? tracked
     : state == TrackingState::kPredicted   ? predicted
     : state == TrackingState::kLost        ? lost
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

  /// "tracking lost for 1.2 s (36 frames)" during a loss, else empty.
  std::string lossNote() const {
    const Utime start = loss_start_utime.load(std::memory_order_relaxed);
    if (start < 0) return {};
    std::ostringstream out;
    out.precision(2);
    out << std::fixed << "tracking lost for "
        << utimeToSeconds(latest_utime.load(std::memory_order_relaxed) - start) << " s ("
        << loss_frames.load(std::memory_order_relaxed) << " frames)";
    return out.str();
  }
};

/// Why frames are dropped at a stage's input, for the exit summary.
const char* dropReason(const std::string& stage) {
  if (stage == "tracking") return "tracking slower than frames arrive";
  if (stage == "vanishing") return "vanishing-point detection slower than frames arrive";
  if (stage == "mapping") return "mapping takes the newest frame and skips the rest";
  return "its queue was full";
}

/// Largest distance a keyframe moves between two sets of poses: translation plus the rotation
/// angle times a 2 m lever arm (a point 2 m in front of the camera), metres.
double largestKeyframeShiftM(const std::unordered_map<std::int64_t, SE3>& before,
                             const std::vector<std::pair<std::int64_t, SE3>>& after) {
  constexpr double kLeverArmM = 2.0;
  double largest_m = 0.0;
  for (const auto& [id, T_after] : after) {
    const auto it = before.find(id);
    if (it == before.end()) continue;
    const SE3 delta = it->second.inverse() * T_after;
    const double angle_rad = Eigen::AngleAxisd(delta.linear()).angle();
    largest_m = std::max(largest_m, delta.translation().norm() + kLeverArmM * angle_rad);
  }
  return largest_m;
}
}  // namespace

struct SlamDaemon::Impl {
  // --- configuration (read once, on the constructing thread) -------------------------------
  Config& config;
  DaemonConfig daemon;
  ChannelConfig channels;
  TrackingConfig tracking_config;
  FilterConfig filter_config;
  MappingConfig mapping_config;
  BackendConfig backend_config;
  LcmFramePublisherConfig frame_publisher_config;
  std::unique_ptr<FrameSource> source;
  /// Owned by the mapping thread while the pipeline runs, by the control thread after it stopped.
  std::unique_ptr<Mapper> mapper;
  /// Control loop (producer) -> mapping thread (consumer).
  SpscQueue<MapRequest> map_requests{16};
  /// Owned by the back-end thread while the pipeline runs, by the control thread after it stopped.
  std::unique_ptr<BackendStage> backend;
  /// Back-end thread (producer) -> publish thread and mapping thread (consumers): each takes the
  /// newest correction it finds.
  SpscQueue<PoseCorrection> publish_corrections{64};
  SpscQueue<BackendCorrection> mapping_corrections{64};
  /// Vanishing-point thread (producer) -> filter thread (consumer), in frame order.
  SpscQueue<VanishingPointPacket> vanishing_points{256};
  WakeSignal vanishing_point_ready;
  /// Detections the filter gave up waiting for, and ones that found the queue full.
  std::atomic<std::uint64_t> vanishing_points_late{0};
  std::atomic<std::uint64_t> vanishing_points_overflowed{0};
  std::atomic<std::int32_t> backend_keyframes{0};
  std::atomic<std::int32_t> backend_loops{0};
  std::atomic<std::int32_t> backend_relocalizations{0};
  std::atomic<std::int64_t> map_leaf_voxels{0};
  std::atomic<std::int64_t> map_occupied_voxels{0};

  // --- control shared with the stages (atomics only) ----------------------------------------
  std::atomic<bool> paused{false};
  /// Wakes the capture thread when RESUME (or shutdown) ends a pause.
  WakeSignal resume_signal;
  /// Live frames read and thrown away while paused.
  std::atomic<std::uint64_t> frames_dropped_paused{0};
  /// Incremented by RESET; each stage resets when it sees a new value.
  std::atomic<std::uint64_t> reset_generation{0};
  std::atomic<int> tracking_state{static_cast<int>(TrackingState::kNotInitialized)};

  /// Commands from the LCM receive thread (producer) to the control loop (consumer).
  SpscQueue<slamd::command_t> commands{kCommandQueueCapacity};
  std::atomic<std::uint64_t> commands_dropped{0};
  /// Commands refused by the control loop (a SAVE_MAP path outside daemon.save_dir).
  std::atomic<std::uint64_t> commands_refused{0};

  /// Capture-to-publication latency, recorded by the publish thread.
  LatencyHistogram end_to_end;
  TrackingTally tracking_tally;

  // --- owned by the publish thread while running, by the control thread after stop ----------
  Trajectory trajectory;

  DaemonSummary summary;

  // --- owned by the mapping thread -------------------------------------------------------------
  bool snapshot_failing = false;  ///< the last periodic snapshot failed

  Impl(Config& c, const DaemonOverrides& overrides) : config(c) {
    daemon = DaemonConfig::load(config);
    if (!overrides.source.empty()) daemon.source = overrides.source;
    if (!overrides.trajectory_out.empty()) daemon.trajectory_out = overrides.trajectory_out;
    if (!overrides.map_out.empty()) daemon.map_out = overrides.map_out;
    if (!overrides.groundtruth_out.empty()) daemon.groundtruth_out = overrides.groundtruth_out;
    if (!overrides.metrics_out.empty()) daemon.metrics_out = overrides.metrics_out;
    if (!overrides.lcm_url.empty()) config.set("lcm.url", overrides.lcm_url);
    checkOutputsAreDistinct();
    channels = ChannelConfig::load(config);
    tracking_config = TrackingConfig::load(config);
    filter_config = FilterConfig::load(config);
    mapping_config = MappingConfig::load(config);
    backend_config = BackendConfig::load(config);
    if (daemon.publish_frames) frame_publisher_config = LcmFramePublisherConfig::load(config);
    if (mapping_config.enabled) mapper = std::make_unique<Mapper>(mapping_config);
    if (backend_config.enabled) {
      std::shared_ptr<const Vocabulary> vocabulary;
      try {
        vocabulary = loadOrTrainVocabulary(backend_config);
      } catch (const VocabularyError& e) {
        throw ConfigError(std::string("backend.vocabulary_file: ") + e.what());
      }
      backend = std::make_unique<BackendStage>(backend_config, std::move(vocabulary));
    }
    // The source reads its own sections (camera.*, capture.*, synthetic.*) now, so that every
    // configuration error surfaces before anything starts.
    source = createFrameSource(daemon.source, config);
    if (overrides.wrap_source) source = overrides.wrap_source(std::move(source));
    removeStaleTemporaryFilesOfOutputs();
  }

  int run(ShutdownSignals& signals);
  /// Throws ConfigError when two outputs name the same file (one would overwrite the other).
  void checkOutputsAreDistinct() const;
  /// Removes what an earlier run killed during a save left behind ("<output>.tmp"), logged.
  void removeStaleTemporaryFilesOfOutputs() const;
  void handleCommands(ShutdownSignals& signals);
  void publishStatus(LcmBus& bus, StatusBuilder& builder, Pipeline& pipeline, const std::string& note);
  int writeOutputs();
  void runMappingStep(LcmBus& bus, const EstimatedPacket& packet, MappingThreadState& state);
  void applyMapCorrections(MappingThreadState& state);
  std::optional<VanishingPoint> takeVanishingPoint(Utime utime, bool live,
                                                  std::optional<VanishingPointPacket>& held);
  void runBackendStep(LcmBus& bus, const EstimatedPacket& packet, std::uint64_t& reset_seen);
  void finishBackend();
  void serveMapRequest(LcmBus& bus, const MapRequest& request);
  void publishMapOutputs(LcmBus& bus, const MapperOutputs& outputs);
  /// False (logged) when the file could not be written.
  bool writeMetrics(const std::vector<StageStats>& stats, const LatencySummary& end_to_end_latency);
  void logTrackingSummary() const;
  void logDropSummary(const std::vector<StageStats>& stats,
                      const FrameSourceStats& source_stats) const;
};

SlamDaemon::SlamDaemon(Config& config, const DaemonOverrides& overrides)
    : impl_(std::make_unique<Impl>(config, overrides)) {}

SlamDaemon::~SlamDaemon() = default;

int SlamDaemon::run(ShutdownSignals& signals) { return impl_->run(signals); }

const DaemonSummary& SlamDaemon::summary() const { return impl_->summary; }

void SlamDaemon::Impl::checkOutputsAreDistinct() const {
  const std::pair<const char*, const std::string*> outputs[] = {
      {"trajectory", &daemon.trajectory_out},
      {"map", &daemon.map_out},
      {"ground truth", &daemon.groundtruth_out},
      {"metrics", &daemon.metrics_out}};
  for (std::size_t i = 0; i < std::size(outputs); ++i) {
    for (std::size_t j = i + 1; j < std::size(outputs); ++j) {
      if (outputs[i].second->empty() || outputs[j].second->empty()) continue;
      std::error_code ignored;
      const auto a = std::filesystem::weakly_canonical(*outputs[i].second, ignored);
      const auto b = std::filesystem::weakly_canonical(*outputs[j].second, ignored);
      if (a == b) {
        throw ConfigError(std::string("the ") + outputs[i].first + " and the " +
                          outputs[j].first + " outputs both name " + *outputs[i].second +
                          ": one would overwrite the other");
      }
    }
  }
}

void SlamDaemon::Impl::removeStaleTemporaryFilesOfOutputs() const {
  const std::vector<std::string> removed = removeStaleTemporaryFiles(
      {daemon.trajectory_out, daemon.map_out, daemon.map_save_path, daemon.groundtruth_out,
       daemon.metrics_out, mapping_config.snapshot_path},
      daemon.save_dir, {".bt", ".ot"});
  for (const std::string& path : removed) {
    SLAMD_LOG_WARN(kLog) << "removed " << path
                         << ", a temporary file left by an interrupted save (the file it was "
                            "replacing is intact)";
  }
}

void SlamDaemon::Impl::handleCommands(ShutdownSignals& signals) {
  while (auto command = commands.tryPop()) {
    switch (command->command) {
      case slamd::command_t::PAUSE:
        SLAMD_LOG_INFO(kLog) << "command PAUSE: capture paused";
        paused.store(true, std::memory_order_release);
        break;
      case slamd::command_t::RESUME:
        SLAMD_LOG_INFO(kLog) << "command RESUME";
        paused.store(false, std::memory_order_release);
        resume_signal.notify();
        break;
      case slamd::command_t::RESET:
        SLAMD_LOG_INFO(kLog) << "command RESET: tracking, filter and map start over";
        reset_generation.fetch_add(1, std::memory_order_acq_rel);
        break;
      case slamd::command_t::SHUTDOWN:
        SLAMD_LOG_INFO(kLog) << "command SHUTDOWN";
        signals.request();
        break;
      case slamd::command_t::SAVE_MAP:
      case slamd::command_t::PUBLISH_MAP: {
        if (!mapper) {
          SLAMD_LOG_WARN(kLog) << "map command ignored: mapping is disabled (mapping.enabled)";
          break;
        }
        MapRequest request;
        request.kind = command->command == slamd::command_t::SAVE_MAP ? MapRequest::Kind::kSave
                                                                       : MapRequest::Kind::kPublish;
        request.path = !daemon.map_out.empty() ? daemon.map_out : daemon.map_save_path;
        if (request.kind == MapRequest::Kind::kSave && !command->argument.empty()) {
          // The file named by a peer on the network: confined to daemon.save_dir.
          std::string error;
          const std::optional<std::string> path =
              resolveCommandSavePath(command->argument, daemon.save_dir, error);
          if (!path) {
            commands_refused.fetch_add(1, std::memory_order_relaxed);
            SLAMD_LOG_WARN(kLog) << error;
            break;
          }
          std::error_code ignored;
          std::filesystem::create_directories(daemon.save_dir, ignored);
          request.path = *path;
        }
        SLAMD_LOG_INFO(kLog) << "command "
                             << (request.kind == MapRequest::Kind::kSave ? "SAVE_MAP " + request.path
                                                                         : std::string("PUBLISH_MAP"));
        if (!map_requests.tryPush(std::move(request))) {
          SLAMD_LOG_WARN(kLog) << "map command dropped: too many pending map requests";
        }
        break;
      }
      default:
        SLAMD_LOG_WARN(kLog) << "unknown command " << static_cast<int>(command->command)
                             << " ignored";
        break;
    }
  }
}

void SlamDaemon::Impl::publishStatus(LcmBus& bus, StatusBuilder& builder, Pipeline& pipeline,
                                     const std::string& note) {
  StatusExtras extras;
  const FrameSourceStats source_stats = source->stats();
  extras.extra_errors["capture"] = source_stats.frames_skipped;
  extras.extra_drops["capture"] =
      source_stats.frames_dropped + frames_dropped_paused.load(std::memory_order_relaxed);
  extras.extra_drops["vanishing"] = vanishing_points_late.load(std::memory_order_relaxed) +
                                    vanishing_points_overflowed.load(std::memory_order_relaxed);
  extras.tracking_state = static_cast<TrackingState>(tracking_state.load(std::memory_order_relaxed));
  extras.map_occupied_voxels = map_occupied_voxels.load(std::memory_order_relaxed);
  extras.map_total_voxels = map_leaf_voxels.load(std::memory_order_relaxed);
  extras.num_keyframes = backend_keyframes.load(std::memory_order_relaxed);
  extras.num_loops = backend_loops.load(std::memory_order_relaxed);
  extras.num_relocalizations = backend_relocalizations.load(std::memory_order_relaxed);
  extras.message = note;
  const std::string loss = tracking_tally.lossNote();
  if (!loss.empty()) extras.message += (extras.message.empty() ? "" : "; ") + loss;
  if (commands_refused.load(std::memory_order_relaxed) > 0) {
    extras.message += (extras.message.empty() ? "" : "; ") +
                      std::to_string(commands_refused.load(std::memory_order_relaxed)) +
                      " commands refused";
  }
  if (source_stats.frames_behind_schedule > 0) {
    extras.message += (extras.message.empty() ? "" : "; ") +
                      std::to_string(source_stats.frames_behind_schedule) +
                      " frames passed over: capture behind its real-time schedule";
  }
  const std::uint64_t malformed = bus.malformedTotal();
  if (malformed > 0) {
    extras.message += (extras.message.empty() ? "" : "; ") + std::to_string(malformed) +
                      " malformed messages received";
  }
  bus.publishMessage(channels.status, builder.build(wallClockUtime(), steadyNowNs(),
                                                    pipeline.stats(), end_to_end.snapshot(),
                                                    extras));
}

int SlamDaemon::Impl::run(ShutdownSignals& signals) {
  const std::int64_t start_ns = steadyNowNs();
  cv::setNumThreads(daemon.opencv_threads);
  try {
    source->open();
  } catch (const SourceError& e) {
    SLAMD_LOG_ERROR(kLog) << "cannot open source '" << daemon.source << "': " << e.what();
    return kExitSourceError;
  }
  SLAMD_LOG_INFO(kLog) << "source: " << source->description()
                       << (source->isLive() ? " (live: frames are dropped, never queued, when "
                                              "tracking falls behind)"
                                            : "");
  SLAMD_LOG_INFO(kLog) << "stages: capture, tracking (" << frontEndName(tracking_config.frontend)
                       << "), filter ("
                       << (filter_config.enabled
                               ? (filter_config.vanishing_points ? "EKF + vanishing points"
                                                                 : "EKF, no vanishing points")
                               : "off: odometry chained")
                       << "), publish, mapping ("
                       << (mapper ? (mapping_config.keyframes_only ? "keyframes" : "every frame")
                                  : "off")
                       << "), back end ("
                       << (backend ? "loop closing, relocalisation, pose graph"
                                   : "off: backend.enabled is false")
                       << ")";

  std::unique_ptr<LcmBus> bus;
  try {
    bus = std::make_unique<LcmBus>(channels.lcm_url);
  } catch (const std::exception& e) {
    SLAMD_LOG_ERROR(kLog) << e.what();
    return kExitFailure;
  }
  bus->subscribe<slamd::command_t>(channels.command,
                                   [this](const slamd::command_t& command, Utime) {
                                     if (!commands.tryPush(command)) {
                                       commands_dropped.fetch_add(1, std::memory_order_relaxed);
                                     }
                                   });
  bus->startHandling();

  const bool live = source->isLive();
  // Datasets played as fast as possible wait for slow stages (nothing is lost, runs are
  // repeatable); live and real-time sources must never be held up, so their frames are dropped
  // oldest-first and counted.
  const EdgePolicy capture_policy = live ? EdgePolicy::kDropOldest : EdgePolicy::kBackpressure;
  // Frames are republished from the capture thread, which alone uses this publisher.
  std::optional<LcmFramePublisher> frame_publisher;
  if (daemon.publish_frames) frame_publisher.emplace(bus->connection(), frame_publisher_config);

  Pipeline pipeline(PipelineMode::kThreaded);
  std::int64_t last_emit_ns = steadyNowNs();
  const auto heartbeat_ns = static_cast<std::int64_t>(daemon.heartbeat_period_s * 1e9);
  auto captured = pipeline.addSource<CapturePacket>("capture", [&]() -> SourceStep<CapturePacket> {
    if (paused.load(std::memory_order_acquire) && !live) {
      // A recording simply waits; a live source keeps being read (below) so that resuming
      // continues from the present, not from a stale buffered frame.
      const auto seen = resume_signal.epoch();
      if (paused.load(std::memory_order_acquire) && steadyNowNs() - last_emit_ns < heartbeat_ns) {
        resume_signal.waitFor(seen, std::chrono::steady_clock::now() +
                                        std::chrono::nanoseconds(heartbeat_ns));
        return SourceStep<CapturePacket>::idle();
      }
      last_emit_ns = steadyNowNs();
      return SourceStep<CapturePacket>::of(CapturePacket{});
    }
    FrameRead read = source->next(std::chrono::milliseconds(100));
    if (read.status == FrameRead::Status::kEndOfStream) return SourceStep<CapturePacket>::end();
    if (read.status == FrameRead::Status::kFrame && paused.load(std::memory_order_acquire)) {
      frames_dropped_paused.fetch_add(1, std::memory_order_relaxed);
    } else if (read.status == FrameRead::Status::kFrame) {
      auto frame = std::make_shared<RgbdFrame>(*read.frame);  // shallow: images are shared
      if (frame->received_steady_ns == 0) frame->received_steady_ns = steadyNowNs();
      ensureGray(*frame);
      if (frame_publisher) frame_publisher->publish(*frame);
      last_emit_ns = steadyNowNs();
      return SourceStep<CapturePacket>::of(CapturePacket{std::move(frame)});
    }
    if (steadyNowNs() - last_emit_ns >= heartbeat_ns) {
      last_emit_ns = steadyNowNs();
      return SourceStep<CapturePacket>::of(CapturePacket{});
    }
    return SourceStep<CapturePacket>::idle();
  });

  VisualOdometry odometry(tracking_config);
  std::uint64_t tracking_reset_seen = 0;
  auto tracked = pipeline.addStage<CapturePacket, TrackedPacket>(
      "tracking", captured, {static_cast<std::size_t>(daemon.tracking_queue), capture_policy},
      [&](CapturePacket packet) -> std::optional<TrackedPacket> {
        const auto generation = reset_generation.load(std::memory_order_acquire);
        if (generation != tracking_reset_seen) {
          odometry.reset();
          tracking_reset_seen = generation;
        }
        TrackedPacket out;
        out.frame = std::move(packet.frame);
        if (out.frame) {
          out.odometry = odometry.processFrame(out.frame);
          tracking_state.store(static_cast<int>(out.odometry->tracking_state),
                               std::memory_order_relaxed);
        }
        return out;
      });

  // Vanishing points: detected on their own thread in parallel with tracking, joined to the
  // tracked frame by the filter thread.
  const bool vanishing_point_thread = daemon.vanishing_point_thread && filter_config.enabled &&
                                      filter_config.vanishing_points;
  std::optional<VanishingPointDetector> vanishing_point_detector;  // vanishing-point thread
  if (vanishing_point_thread) {
    pipeline.addSink<CapturePacket>(
        "vanishing", captured,
        {static_cast<std::size_t>(daemon.tracking_queue), capture_policy},
        [&](CapturePacket packet) {
          if (!packet.frame) return;
          if (!vanishing_point_detector) {
            vanishing_point_detector.emplace(filter_config, packet.frame->intrinsics);
          }
          VanishingPointPacket out{packet.frame->utime,
                                   vanishing_point_detector->detect(packet.frame->gray)};
          if (!vanishing_points.tryPush(std::move(out))) {
            vanishing_points_overflowed.fetch_add(1, std::memory_order_relaxed);
          }
          vanishing_point_ready.notify();
        });
  }

  PoseEstimator estimator(filter_config, vanishing_point_thread
                                             ? VanishingPointSource::kPrecomputed
                                             : VanishingPointSource::kDetectHere);
  std::optional<VanishingPointPacket> held_vanishing_point;  // filter thread
  std::uint64_t filter_reset_seen = 0;
  auto estimated = pipeline.addStage<TrackedPacket, EstimatedPacket>(
      "filter", tracked, {static_cast<std::size_t>(daemon.filter_queue), EdgePolicy::kBackpressure},
      [&](TrackedPacket packet) -> std::optional<EstimatedPacket> {
        const auto generation = reset_generation.load(std::memory_order_acquire);
        if (generation != filter_reset_seen) {
          estimator.reset();
          filter_reset_seen = generation;
        }
        if (vanishing_point_thread && packet.frame) {
          packet.vanishing_point =
              takeVanishingPoint(packet.frame->utime, live, held_vanishing_point);
        }
        return estimator.process(std::move(packet));
      });

  SE3 publish_correction = SE3::Identity();  // owned by the publish thread
  bool publish_corrected = false;
  bool publish_relocalized = false;
  std::uint64_t publish_reset_seen = 0;
  pipeline.addSink<EstimatedPacket>(
      "publish", estimated,
      {static_cast<std::size_t>(daemon.publish_queue), EdgePolicy::kBackpressure},
      [&](EstimatedPacket packet) {
        const auto generation = reset_generation.load(std::memory_order_acquire);
        if (generation != publish_reset_seen) {
          publish_correction = SE3::Identity();
          publish_corrected = false;
          publish_reset_seen = generation;
        }
        while (auto correction = publish_corrections.tryPop()) {
          publish_correction = correction->T_world_uncorrected;
          publish_relocalized = publish_relocalized || correction->relocalized;
          publish_corrected = true;
        }
        if (!packet.frame || !packet.odometry) return;
        PoseEstimate pose = packet.pose;
        if (publish_corrected) {
          pose = transformedPose(pose, publish_correction);
          pose.source = PoseSource::kOptimized;
        }
        if (publish_relocalized && pose.tracking_state == TrackingState::kOk) {
          pose.tracking_state = TrackingState::kRelocalized;
          publish_relocalized = false;
        }
        pose.parent_frame = daemon.world_frame;
        pose.child_frame = daemon.camera_frame;
        tracking_tally.record(pose.tracking_state, pose.utime);
        bus->publishMessage(channels.pose, toPoseMessage(pose));
        bus->publishMessage(channels.bot_pose, toBotCorePose(pose));
        end_to_end.recordNs(steadyNowNs() - packet.frame->received_steady_ns);
        bus->publishMessage(channels.odometry, toOdometryMessage(*packet.odometry));
        if (packet.vanishing_point) {
          bus->publishMessage(channels.vanishing_point,
                              toVanishingPointMessage(pose.utime, *packet.vanishing_point));
        }
        // A lost pose, or the placeholder before tracking could start, is not an estimate.
        if (pose.tracking_state != TrackingState::kLost &&
            pose.tracking_state != TrackingState::kNotInitialized) {
          trajectory.push_back(StampedPose{utimeToSeconds(pose.utime), pose.T_world_camera});
        }
      });

  MappingThreadState mapping_state;
  if (mapper) {
    pipeline.addSink<EstimatedPacket>(
        "mapping", estimated,
        {static_cast<std::size_t>(daemon.mapping_queue),
         live ? EdgePolicy::kDrainToNewest : EdgePolicy::kBackpressure},
        [&](EstimatedPacket packet) { runMappingStep(*bus, packet, mapping_state); });
    pipeline.setStageNice("mapping", daemon.mapping_nice);
  }

  std::uint64_t backend_reset_seen = 0;
  if (backend) {
    pipeline.addSink<EstimatedPacket>(
        "backend", estimated,
        {static_cast<std::size_t>(daemon.backend_queue), EdgePolicy::kBackpressure},
        [&](EstimatedPacket packet) { runBackendStep(*bus, packet, backend_reset_seen); });
    pipeline.setStageNice("backend", daemon.backend_nice);
  }

  StatusBuilder status_builder;
  pipeline.start();
  SLAMD_LOG_INFO(kLog) << "running; LCM " << (channels.lcm_url.empty() ? "<default URL>" : channels.lcm_url)
                       << ", poses on " << channels.pose << ", status on " << channels.status
                       << ", commands on " << channels.command;
  const auto status_period_ns = static_cast<std::int64_t>(daemon.status_period_s * 1e9);
  std::int64_t next_status_ns = steadyNowNs() + status_period_ns;
  std::string stop_reason = "end of input";
  while (true) {
    if (signals.waitFor(std::chrono::milliseconds(20))) {
      stop_reason = signals.signalNumber() ? "signal " + std::to_string(signals.signalNumber())
                                           : "SHUTDOWN command";
      break;
    }
    handleCommands(signals);
    if (steadyNowNs() >= next_status_ns) {
      publishStatus(*bus, status_builder, pipeline, paused.load() ? "paused" : "");
      next_status_ns += status_period_ns;
    }
    if (pipeline.waitUntilFinished(std::chrono::steady_clock::now())) break;
  }
  SLAMD_LOG_INFO(kLog) << "stopping (" << stop_reason << "): draining queued frames";
  paused.store(false, std::memory_order_release);
  resume_signal.notify();
  const StopReport stop = pipeline.stop(std::chrono::milliseconds(
      static_cast<std::int64_t>(daemon.drain_deadline_s * 1000.0)));
  if (!stop.drained) {
    SLAMD_LOG_WARN(kLog) << "drain deadline passed; " << stop.discarded << " frames discarded";
  }
  source->close();
  publishStatus(*bus, status_builder, pipeline, "stopped: " + stop_reason);
  bus->stopHandling();

  // Summary (the pipeline's threads are joined: their counters are final).
  const auto stats = pipeline.stats();
  auto processed = [&stats](const std::string& stage) -> std::uint64_t {
    for (const auto& s : stats) {
      if (s.name == stage) return s.processed;
    }
    return 0;
  };
  summary.frames_captured = processed("capture");
  summary.frames_tracked = processed("tracking");
  summary.poses_published = processed("publish");
  if (mapper) summary.frames_mapped = static_cast<std::uint64_t>(mapper->stats().frames_integrated);
  // The mapping thread has stopped: map requests that arrived during the drain are served here.
  while (auto request = map_requests.tryPop()) serveMapRequest(*bus, *request);
  for (const auto& stage : stats) {
    summary.errors += stage.errors;
    for (const auto& edge : stage.inputs) summary.drops += edge.dropped + edge.discarded;
  }
  const FrameSourceStats source_stats = source->stats();
  summary.errors += source_stats.frames_skipped;
  summary.drops += source_stats.frames_dropped + frames_dropped_paused.load() +
                   commands_dropped.load();
  summary.frames_behind_schedule = source_stats.frames_behind_schedule;
  summary.frames_over_rate = source_stats.frames_over_rate;
  for (const auto& stage : stats) {
    if (stage.name != "tracking") continue;
    for (const auto& edge : stage.inputs) {
      summary.frames_dropped_before_tracking += edge.dropped + edge.discarded;
    }
  }
  summary.poses_tracked = tracking_tally.tracked.load();
  summary.poses_predicted = tracking_tally.predicted.load();
  summary.poses_lost = tracking_tally.lost.load();
  summary.poses_not_initialized = tracking_tally.not_initialized.load();
  summary.longest_loss_s = tracking_tally.longest_loss_s;
  summary.tracking_lost_at_end = tracking_tally.loss_start_utime.load() >= 0;
  summary.capture_gaps = tracking_tally.capture_gaps;
  summary.longest_capture_gap_s = tracking_tally.longest_capture_gap_s;
  summary.longest_resume_s = tracking_tally.longest_resume_s;
  summary.resumed_after_last_gap = tracking_tally.gap_return_utime < 0;
  summary.malformed_commands = bus->malformedCount(channels.command);
  summary.commands_refused = commands_refused.load();
  if (summary.commands_refused > 0) {
    SLAMD_LOG_WARN(kLog) << "commands: " << summary.commands_refused
                         << " refused (SAVE_MAP outside daemon.save_dir " << daemon.save_dir
                         << ")";
  }
  summary.duration_s = static_cast<double>(steadyNowNs() - start_ns) * 1e-9;
  const LatencySummary latency = end_to_end.summary();
  summary.end_to_end_p50_ms = latency.p50_ms;
  summary.end_to_end_p95_ms = latency.p95_ms;
  summary.end_to_end_p99_ms = latency.p99_ms;
  for (const auto& stage : stats) {
    std::uint64_t dropped = 0;
    for (const auto& edge : stage.inputs) dropped += edge.dropped + edge.discarded;
    SLAMD_LOG_INFO(kLog) << "stage " << stage.name << ": " << stage.processed << " processed"
                         << (stage.heartbeats > 0
                                 ? " (and " + std::to_string(stage.heartbeats) + " heartbeats)"
                                 : std::string())
                         << ", " << dropped << " dropped at its input, " << stage.errors
                         << " errors; time per item p50 " << stage.latency.p50_ms << " ms, p95 "
                         << stage.latency.p95_ms << " ms, p99 " << stage.latency.p99_ms << " ms";
  }
  SLAMD_LOG_INFO(kLog) << "frames: " << summary.frames_captured << " captured, "
                       << summary.frames_tracked << " tracked, " << summary.poses_published
                       << " poses published; " << summary.drops << " dropped, " << summary.errors
                       << " errors, " << bus->malformedTotal() << " malformed messages; "
                       << summary.duration_s << " s; capture-to-pose latency p50 "
                       << latency.p50_ms << " ms, p95 " << latency.p95_ms << " ms, p99 "
                       << latency.p99_ms << " ms";
  logTrackingSummary();
  logDropSummary(stats, source_stats);
  if (source_stats.clock_reanchors > 0) {
    SLAMD_LOG_WARN(kLog) << "source: its clock jumped and was re-anchored "
                         << source_stats.clock_reanchors << " times (see the capture warnings)";
  }
  if (vanishing_points_late.load() + vanishing_points_overflowed.load() > 0) {
    SLAMD_LOG_INFO(kLog) << "vanishing points: " << vanishing_points_late.load()
                         << " frames filtered without their detection (late or dropped), "
                         << vanishing_points_overflowed.load() << " detections overflowed";
  }
  const bool metrics_written = daemon.metrics_out.empty() || writeMetrics(stats, latency);
  if (backend) finishBackend();
  const int outputs = writeOutputs();
  return outputs != kExitOk ? outputs : metrics_written ? kExitOk : kExitOutputError;
}

void SlamDaemon::Impl::logTrackingSummary() const {
  std::ostringstream line;
  line.precision(2);
  line << std::fixed << "tracking: " << summary.poses_tracked << " of " << summary.poses_published
       << " poses measured, " << summary.poses_predicted << " predicted, " << summary.poses_lost
       << " lost, " << summary.poses_not_initialized << " before the first; longest loss "
       << summary.longest_loss_s << " s";
  if (summary.poses_published == 0) {
    SLAMD_LOG_WARN(kLog) << "tracking: no pose was published";
  } else if (summary.poses_tracked == 0) {
    SLAMD_LOG_WARN(kLog) << line.str() << "; NO POSE WAS MEASURED: tracking never started";
  } else if (summary.tracking_lost_at_end) {
    SLAMD_LOG_WARN(kLog) << line.str() << "; tracking LOST at the end ("
                         << tracking_tally.lossNote() << ")";
  } else if (summary.poses_predicted + summary.poses_lost > 0) {
    SLAMD_LOG_WARN(kLog) << line.str() << "; tracking OK at the end";
  } else {
    SLAMD_LOG_INFO(kLog) << line.str() << "; tracking OK throughout";
  }
  if (summary.capture_gaps > 0) {
    std::ostringstream gaps;
    gaps.precision(2);
    gaps << std::fixed << "capture: " << summary.capture_gaps
         << " gaps in the camera's frames (longest " << summary.longest_capture_gap_s
         << " s); tracking measured again at most " << summary.longest_resume_s
         << " s after the frames returned";
    if (!summary.resumed_after_last_gap) gaps << ", but NOT after the last gap";
    SLAMD_LOG_WARN(kLog) << gaps.str();
  }
}

void SlamDaemon::Impl::logDropSummary(const std::vector<StageStats>& stats,
                                      const FrameSourceStats& source_stats) const {
  if (summary.drops == 0) {
    SLAMD_LOG_INFO(kLog) << "drops: none";
    return;
  }
  std::ostringstream line;
  line << "drops: " << summary.drops << " in all";
  if (source_stats.frames_behind_schedule > 0) {
    line << "; " << source_stats.frames_behind_schedule
         << " frames passed over by the source, behind its real-time schedule (reading, decoding "
            "or rendering, or the CPU it shares, was too slow)";
  }
  if (source_stats.frames_over_rate > 0) {
    line << "; " << source_stats.frames_over_rate
         << " received faster than a camera sends them (capture.lcm.max_rate_hz), not decoded";
  }
  const std::uint64_t lost = source_stats.frames_dropped - source_stats.frames_behind_schedule -
                             source_stats.frames_over_rate;
  if (lost > 0) {
    line << "; " << lost << " lost by the source (device or receive buffer overflow)";
  }
  for (const auto& stage : stats) {
    std::uint64_t dropped = 0;
    for (const auto& edge : stage.inputs) dropped += edge.dropped + edge.discarded;
    if (dropped > 0) {
      line << "; " << dropped << " at the input of " << stage.name << " ("
           << dropReason(stage.name) << ")";
    }
  }
  if (frames_dropped_paused.load() > 0) {
    line << "; " << frames_dropped_paused.load() << " frames read while paused";
  }
  if (commands_dropped.load() > 0) {
    line << "; " << commands_dropped.load() << " commands (command queue full)";
  }
  SLAMD_LOG_WARN(kLog) << line.str();
}

bool SlamDaemon::Impl::writeMetrics(const std::vector<StageStats>& stats,
                                    const LatencySummary& end_to_end_latency) {
  eval::JsonWriter json(true);
  json.beginObject();
  json.key("program").value("slamd");
  json.key("source").value(daemon.source);
  json.key("live").value(source->isLive());
  json.key("frames_captured").value(static_cast<std::int64_t>(summary.frames_captured));
  json.key("poses_published").value(static_cast<std::int64_t>(summary.poses_published));
  json.key("frames_mapped").value(static_cast<std::int64_t>(summary.frames_mapped));
  json.key("poses_tracked").value(static_cast<std::int64_t>(summary.poses_tracked));
  json.key("poses_predicted").value(static_cast<std::int64_t>(summary.poses_predicted));
  json.key("poses_lost").value(static_cast<std::int64_t>(summary.poses_lost));
  json.key("longest_loss_s").value(summary.longest_loss_s);
  json.key("tracking_lost_at_end").value(summary.tracking_lost_at_end);
  json.key("capture_gaps").value(static_cast<std::int64_t>(summary.capture_gaps));
  json.key("longest_capture_gap_s").value(summary.longest_capture_gap_s);
  json.key("longest_resume_s").value(summary.longest_resume_s);
  json.key("resumed_after_last_gap").value(summary.resumed_after_last_gap);
  json.key("frames_behind_schedule").value(static_cast<std::int64_t>(summary.frames_behind_schedule));
  json.key("frames_over_rate").value(static_cast<std::int64_t>(summary.frames_over_rate));
  json.key("frames_dropped_before_tracking")
      .value(static_cast<std::int64_t>(summary.frames_dropped_before_tracking));
  json.key("drops").value(static_cast<std::int64_t>(summary.drops));
  json.key("malformed_commands").value(static_cast<std::int64_t>(summary.malformed_commands));
  json.key("commands_refused").value(static_cast<std::int64_t>(summary.commands_refused));
  json.key("errors").value(static_cast<std::int64_t>(summary.errors));
  json.key("duration_s").value(summary.duration_s);
  json.key("fps").value(summary.duration_s > 0
                            ? static_cast<double>(summary.poses_published) / summary.duration_s
                            : 0.0);
  json.key("end_to_end_p50_ms").value(end_to_end_latency.p50_ms);
  json.key("end_to_end_p95_ms").value(end_to_end_latency.p95_ms);
  json.key("end_to_end_p99_ms").value(end_to_end_latency.p99_ms);
  json.key("stages").beginObject();
  for (const auto& stage : stats) {
    json.key(stage.name).beginObject();
    json.key("processed").value(static_cast<std::int64_t>(stage.processed));
    json.key("heartbeats").value(static_cast<std::int64_t>(stage.heartbeats));
    json.key("p50_ms").value(stage.latency.p50_ms);
    json.key("p95_ms").value(stage.latency.p95_ms);
    json.key("p99_ms").value(stage.latency.p99_ms);
    json.endObject();
  }
  json.endObject();
  json.endObject();
  std::string error;
  if (!writeOutputFile(
          daemon.metrics_out,
          [&](std::ostream& out) {
            out << json.str() << "\n";
            return true;
          },
          &error)) {
    SLAMD_LOG_ERROR(kLog) << "metrics not written: " << error;
    return false;
  }
  return true;
}

void SlamDaemon::Impl::publishMapOutputs(LcmBus& bus, const MapperOutputs& outputs) {
  if (outputs.update && !outputs.update->voxels.empty()) {
    bus.publishMessage(channels.map_update, toMapUpdateMessage(*outputs.update));
  }
  if (outputs.full_map) bus.publishMessage(channels.map, toFullMapMessage(*outputs.full_map));
  if (outputs.snapshot) {
    // Logged on each change between failing and succeeding, so a full disk gives one line per
    // retry and one when it recovers, not one per period forever.
    if (!outputs.snapshot->ok) {
      SLAMD_LOG_WARN(kLog) << "map snapshot failed (kept in memory, the previous snapshot is "
                              "intact; retrying): "
                           << outputs.snapshot->error;
    } else if (snapshot_failing) {
      SLAMD_LOG_INFO(kLog) << "map snapshot written again: " << outputs.snapshot->path;
    }
    snapshot_failing = !outputs.snapshot->ok;
  }
}

void SlamDaemon::Impl::serveMapRequest(LcmBus& bus, const MapRequest& request) {
  if (request.kind == MapRequest::Kind::kPublish) {
    bus.publishMessage(channels.map, toFullMapMessage(mapper->fullMap()));
    return;
  }
  const MapFileResult saved = mapper->saveMap(request.path);
  if (saved.ok) {
    SLAMD_LOG_INFO(kLog) << "SAVE_MAP: map written to " << saved.path;
  } else {
    SLAMD_LOG_ERROR(kLog) << "SAVE_MAP failed: " << saved.error;
  }
}

void SlamDaemon::Impl::applyMapCorrections(MappingThreadState& state) {
  std::optional<BackendCorrection> newest;
  while (auto correction = mapping_corrections.tryPop()) newest = std::move(correction);
  if (!newest) return;
  state.T_world_uncorrected = newest->T_world_uncorrected;
  // Re-integrating every keyframe cloud costs about one frame's integration per keyframe: only
  // worth it when the correction moves the map by more than half a voxel.
  const double shift_m = largestKeyframeShiftM(state.keyframe_map_poses, newest->keyframe_poses);
  if (shift_m < 0.5 * mapping_config.resolution_m) return;
  const RebuildResult rebuilt = mapper->rebuild(newest->keyframe_poses);
  for (const auto& [id, T_world_keyframe] : newest->keyframe_poses) {
    auto it = state.keyframe_map_poses.find(id);
    if (it != state.keyframe_map_poses.end()) it->second = T_world_keyframe;
  }
  SLAMD_LOG_INFO(kLog) << "map rebuilt from " << rebuilt.keyframes_integrated
                       << " keyframe clouds after a correction of up to " << shift_m << " m";
}

void SlamDaemon::Impl::runMappingStep(LcmBus& bus, const EstimatedPacket& packet,
                                      MappingThreadState& state) {
  const auto generation = reset_generation.load(std::memory_order_acquire);
  if (generation != state.reset_seen) {
    mapper->reset();
    state.keyframe_map_poses.clear();
    state.T_world_uncorrected = SE3::Identity();
    state.reset_seen = generation;
  }
  applyMapCorrections(state);
  while (auto request = map_requests.tryPop()) serveMapRequest(bus, *request);
  if (packet.frame && packet.odometry &&
      packet.pose.tracking_state != TrackingState::kLost &&
      packet.pose.tracking_state != TrackingState::kNotInitialized &&
      (!mapping_config.keyframes_only || packet.odometry->is_keyframe)) {
    std::optional<std::int64_t> keyframe_id;
    if (packet.odometry->is_keyframe && packet.odometry->keyframe) {
      keyframe_id = packet.odometry->keyframe->id;
    }
    const SE3 T_world_camera = state.T_world_uncorrected * packet.pose.T_world_camera;
    const IntegrationResult result = mapper->integrate(*packet.frame, T_world_camera, keyframe_id);
    if (result.keyframe_cloud_kept && keyframe_id) {
      state.keyframe_map_poses[*keyframe_id] = T_world_camera;
    }
    if (result.status == IntegrationStatus::kBadFrame ||
        result.status == IntegrationStatus::kBadPose) {
      // The pipeline counts a thrown error against this stage and carries on.
      throw std::runtime_error("frame not mapped: " + result.error);
    }
  }
  publishMapOutputs(bus, mapper->poll(mapper->latestUtime()));
  map_leaf_voxels.store(static_cast<std::int64_t>(mapper->numLeafNodes()),
                        std::memory_order_relaxed);
  // Counting occupied voxels walks the tree: once a second is plenty for the status channel.
  if (steadyNowNs() >= state.next_occupancy_count_ns) {
    auto count_occupied = [](const auto* tree) {
      std::int64_t occupied = 0;
      for (auto it = tree->begin_leafs(); it != tree->end_leafs(); ++it) {
        if (tree->isNodeOccupied(*it)) ++occupied;
      }
      return occupied;
    };
    map_occupied_voxels.store(mapper->hasColor() ? count_occupied(mapper->colorOcTree())
                                                 : count_occupied(mapper->ocTree()),
                              std::memory_order_relaxed);
    state.next_occupancy_count_ns = steadyNowNs() + 1'000'000'000;
  }
}

std::optional<VanishingPoint> SlamDaemon::Impl::takeVanishingPoint(
    Utime utime, bool live, std::optional<VanishingPointPacket>& held) {
  // Datasets played as fast as possible wait for every detection (repeatable runs); the generous
  // bound only guards against a detection that never comes (its frame failed on that thread).
  const auto wait = live ? std::chrono::microseconds(
                               static_cast<std::int64_t>(daemon.vanishing_point_wait_ms * 1000.0))
                         : std::chrono::microseconds(2'000'000);
  const auto deadline = std::chrono::steady_clock::now() + wait;
  while (true) {
    const auto seen = vanishing_point_ready.epoch();
    if (!held) held = vanishing_points.tryPop();
    while (held && held->utime < utime) held = vanishing_points.tryPop();  // frames tracking skipped
    if (held && held->utime == utime) {
      std::optional<VanishingPoint> detection = std::move(held->detection);
      held.reset();
      return detection;
    }
    if (held) break;  // the next detection is of a later frame: this frame's was dropped
    if (!vanishing_point_ready.waitFor(seen, deadline)) break;
  }
  vanishing_points_late.fetch_add(1, std::memory_order_relaxed);
  return std::nullopt;
}

void SlamDaemon::Impl::runBackendStep(LcmBus& bus, const EstimatedPacket& packet,
                                      std::uint64_t& reset_seen) {
  const auto generation = reset_generation.load(std::memory_order_acquire);
  if (generation != reset_seen) {
    backend->reset();
    reset_seen = generation;
  }
  std::optional<BackendCorrection> correction = backend->process(packet);
  const BackendStageStats& stats = backend->stats();
  backend_keyframes.store(static_cast<std::int32_t>(stats.keyframes), std::memory_order_relaxed);
  backend_loops.store(static_cast<std::int32_t>(stats.loops), std::memory_order_relaxed);
  backend_relocalizations.store(static_cast<std::int32_t>(stats.relocalizations),
                                std::memory_order_relaxed);
  if (!correction) return;
  correction->trajectory.frame_id = daemon.world_frame;
  bus.publishMessage(channels.keyframes, toKeyframeTrajectoryMessage(correction->trajectory));
  if (!publish_corrections.tryPush(
          PoseCorrection{correction->T_world_uncorrected, correction->relocalized})) {
    // Cannot happen while the publish thread keeps up (it drains on every frame); if it does,
    // the next correction replaces this one anyway.
    SLAMD_LOG_WARN(kLog) << "pose correction not handed to the publish thread: queue full";
  }
  if (mapper && !mapping_corrections.tryPush(std::move(*correction))) {
    SLAMD_LOG_WARN(kLog) << "map correction not handed to the mapping thread: queue full";
  }
}

void SlamDaemon::Impl::finishBackend() {
  const BackendStageStats& stats = backend->stats();
  summary.keyframes = stats.keyframes;
  summary.loops = stats.loops;
  summary.relocalizations = stats.relocalizations;
  summary.optimizations = stats.optimizations;
  summary.max_optimization_ms = stats.max_optimization_ms;
  SLAMD_LOG_INFO(kLog) << "back end: " << stats.keyframes << " keyframes, " << stats.loops
                       << " loops, " << stats.relocalizations << " relocalisations, "
                       << stats.optimizations << " optimisations (longest "
                       << stats.max_optimization_ms << " ms)";
  // The written trajectory and map take the final optimised poses, including corrections that
  // arrived after the publish and mapping threads had finished.
  trajectory = backend->optimizedTrajectory();
  if (mapper && stats.optimizations > 0) {
    std::vector<std::pair<std::int64_t, SE3>> keyframe_poses;
    for (const std::int64_t id : backend->backend().graph().nodeIds()) {
      keyframe_poses.emplace_back(id, backend->backend().pose(id));
    }
    const RebuildResult rebuilt = mapper->rebuild(keyframe_poses);
    SLAMD_LOG_INFO(kLog) << "final map rebuilt from " << rebuilt.keyframes_integrated
                         << " keyframe clouds at their optimised poses";
  }
}

int SlamDaemon::Impl::writeOutputs() {
  int exit_code = kExitOk;
  if (!daemon.trajectory_out.empty()) {
    try {
      writeTumTrajectory(daemon.trajectory_out, trajectory,
                         "slamd trajectory (T_world_camera), source " + daemon.source);
      SLAMD_LOG_INFO(kLog) << "trajectory: " << trajectory.size() << " poses written to "
                           << daemon.trajectory_out;
    } catch (const std::exception& e) {
      SLAMD_LOG_ERROR(kLog) << e.what();
      exit_code = kExitOutputError;
    }
  }
  if (!daemon.groundtruth_out.empty()) {
    const std::optional<Trajectory> truth = source->groundTruth();
    if (!truth) {
      SLAMD_LOG_WARN(kLog) << "--groundtruth-out: source " << daemon.source
                           << " has no ground truth; nothing written";
    } else {
      try {
        writeTumTrajectory(daemon.groundtruth_out, *truth, "ground truth of " + daemon.source);
      } catch (const std::exception& e) {
        SLAMD_LOG_ERROR(kLog) << e.what();
        exit_code = kExitOutputError;
      }
    }
  }
  if (!daemon.map_out.empty()) {
    if (!mapper) {
      SLAMD_LOG_WARN(kLog) << "--map-out " << daemon.map_out
                           << " not written: mapping is disabled (mapping.enabled)";
    } else {
      const MapFileResult saved = mapper->saveMap(daemon.map_out);
      if (saved.ok) {
        SLAMD_LOG_INFO(kLog) << "map: " << mapper->numLeafNodes() << " voxels written to "
                             << saved.path;
      } else {
        SLAMD_LOG_ERROR(kLog) << "map not saved: " << saved.error;
        exit_code = kExitOutputError;
      }
    }
  }
  return exit_code;
}

}  // namespace slamd
