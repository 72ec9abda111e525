#include "slamd/app/slam_daemon.hpp"

#include <malloc.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/app/backend_stage.hpp"
#include "slamd/app/command_save_path.hpp"
#include "slamd/app/daemon_config.hpp"
#include "slamd/app/stage_steps.hpp"
#include "slamd/backend/session.hpp"
#include "slamd/command_t.hpp"
#include "slamd/common/file_io.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/memory_pressure.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/frame_codec.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/lcm_frame_publisher.hpp"
#include "slamd/comms/lcm_relay.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/odometry_codec.hpp"
#include "slamd/comms/plane_map_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/comms/status_codec.hpp"
#include "slamd/eval/json_writer.hpp"
#include "slamd/mapping/mapper.hpp"
#include "slamd/pipeline/pipeline.hpp"
#include "slamd/sources/create_frame_source.hpp"

namespace slamd {

namespace {
constexpr const char* kLog = "slamd";
constexpr std::size_t kCommandQueueCapacity = 64;

/// Why frames are dropped at a stage's input, for the exit summary.
const char* dropReason(const std::string& stage) {
  if (stage == "tracking") return "tracking slower than frames arrive";
  if (stage == "vanishing") return "vanishing-point detection slower than frames arrive";
  if (stage == "mapping") return "mapping takes the newest frame and skips the rest";
  return "its queue was full";
}

/// What the steps publish, on the daemon's LCM channels. Each message is encoded on the calling
/// thread and handed to `send`: the bus itself, or an LcmRelay lane for a niced thread.
class LcmDaemonPublisher final : public DaemonPublisher {
 public:
  using Send = std::function<void(std::string channel, std::vector<std::uint8_t> bytes)>;
  LcmDaemonPublisher(Send send, const ChannelConfig& channels)
      : send_(std::move(send)), channels_(channels) {}

  void publishPose(const PoseEstimate& pose) override {
    send(channels_.pose, toPoseMessage(pose));
    send(channels_.bot_pose, toBotCorePose(pose));
  }
  void publishOdometry(const OdometryResult& odometry) override {
    send(channels_.odometry, toOdometryMessage(odometry));
  }
  void publishVanishingPoint(Utime utime, const VanishingPointReport& report) override {
    send(channels_.vanishing_point, toVanishingPointMessage(utime, report));
  }
  void publishKeyframes(const KeyframeTrajectory& trajectory) override {
    send(channels_.keyframes, toKeyframeTrajectoryMessage(trajectory));
  }
  void publishMapUpdate(const MapUpdate& update) override {
    send(channels_.map_update, toMapUpdateMessage(update));
  }
  void publishFullMap(const FullMap& map) override { send(channels_.map, toFullMapMessage(map)); }
  void publishPlaneMap(const planes::PlaneMapSnapshot& plane_map) override {
    send(channels_.plane_map, toPlaneMapMessage(plane_map));
  }

 private:
  template <typename Message>
  void send(const std::string& channel, const Message& message) {
    send_(channel, encodeMessage(message));
  }

  Send send_;
  const ChannelConfig& channels_;
};

/// The daemon's publishers. The pose path (capture, publish step, control loop) publishes on the
/// bus directly. Mapping and the back end run niced on a live source, so they must never take the
/// LCM connection's lock: a niced thread that holds it (a full map goes out in many fragments under
/// it) while starved of CPU kept every pose waiting, up to a second on a fully loaded machine. Each
/// hands its encoded messages to its own relay lane instead.
struct DaemonPublishers {
  DaemonPublishers(LcmBus& bus, const ChannelConfig& channels)
      : relay(bus),
        direct([&bus](std::string channel,
                      std::vector<std::uint8_t> bytes) { bus.publish(channel, bytes); },
               channels),
        mapping(onto(relay.addLane("mapping", kRelayLaneCapacity)), channels),
        backend(onto(relay.addLane("backend", kRelayLaneCapacity)), channels) {}

  /// Sends into a relay lane (owned by the relay, which outlives the publishers that use it).
  static LcmDaemonPublisher::Send onto(LcmRelay::Lane& lane) {
    return [&lane](std::string channel, std::vector<std::uint8_t> bytes) {
      lane.publish(std::move(channel), std::move(bytes));
    };
  }

  /// A mapping cycle publishes up to three messages (update, full map, planes); a lane this deep
  /// holds several cycles before its (niced) producer has to wait.
  static constexpr std::size_t kRelayLaneCapacity = 16;
  LcmRelay relay;  // first: the publishers below send into its lanes
  LcmDaemonPublisher direct;
  LcmDaemonPublisher mapping;
  LcmDaemonPublisher backend;
};

/// The running daemon's steps and the side queues between them. Optional members are the stages
/// the configuration turned off.
struct DaemonSteps {
  /// Back-end step (producer) -> publish step and mapping step (consumers).
  SpscQueue<PoseCorrection> pose_corrections{64};
  SpscQueue<MapCorrection> map_corrections{64};
  SpscQueue<MapKeyframesPacket> map_keyframes{16};
  VanishingPointChannel vanishing_points;
  PlaneSegmentationChannel plane_segmentation;
  std::optional<LcmFramePublisher> frame_publisher;  ///< used by the capture thread only
  std::optional<CaptureStep> capture;
  std::optional<TrackingStep> tracking;
  std::optional<VanishingPointStep> vanishing;
  std::optional<PlaneSegmentationStep> planes;
  std::optional<FilterStep> filter;
  std::optional<PublishStep> publish;
  std::optional<MappingStep> mapping;
  std::optional<BackendStep> backend;
};

/// Passes each packet of a stage to its step.
template <typename Step>
auto body(Step& step) {
  return [&step](auto packet) { return step.process(std::move(packet)); };
}
}  // namespace

struct SlamDaemon::Impl {
  // --- configuration (read once, on the constructing thread) -------------------------------
  Config& config;  ///< the caller's: used during construction only
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
  /// Built by run() once the LCM bus is up.
  std::unique_ptr<DaemonSteps> steps;
  /// The configuration as read, for sessions (config.effectiveYaml() at construction).
  std::string effective_config_yaml;
  /// The back end's vocabulary (null without a back end).
  std::shared_ptr<const Vocabulary> vocabulary;
  /// The session loaded (--session-in); its back end and map moved into the stages at start.
  std::unique_ptr<Session> session;
  /// With a session: this run's keyframes are numbered from here on.
  std::int64_t first_run_keyframe_id = 0;
  /// Control loop (producer) -> back-end thread (consumer): SAVE_SESSION's snapshot requests.
  SpscQueue<SnapshotRequest> snapshot_requests{4};
  /// A SAVE_SESSION waiting for the back end's snapshot and the mapping thread's map file
  /// (control thread).
  struct SessionSave {
    std::string dir;
    std::future<std::shared_ptr<const BackendSnapshot>> snapshot;
    std::future<SavedMap> map;  ///< not valid without a mapper
    std::string map_path;       ///< where the mapping thread writes it
    std::string clouds_path;    ///< and the keyframe clouds
    std::int64_t started_ns = 0;
  };
  std::optional<SessionSave> session_save;

  /// Commands from the LCM receive thread (producer) to the control loop (consumer).
  SpscQueue<slamd::command_t> commands{kCommandQueueCapacity};
  std::atomic<std::uint64_t> commands_dropped{0};
  /// Commands refused by the control loop (a SAVE_MAP path outside daemon.save_dir).
  std::atomic<std::uint64_t> commands_refused{0};

  /// Owned by the publish thread while running, by the control thread after stop.
  Trajectory trajectory;

  /// Resident memory against daemon.memory_limit_mb: the control loop updates it with every
  /// status message; the mapping and back-end threads read the level and degrade by it.
  MemoryGovernor memory_governor{0.0};
  std::atomic<MemoryPressure> memory_pressure{MemoryPressure::kNone};
  double resident_mb = 0.0;  ///< at the latest status message (control thread)

  /// Capture-to-pose latency minute by minute (control thread, at the status messages).
  WindowedLatency end_to_end_by_minute{60.0};

  DaemonSummary summary;

  Impl(Config& c, const DaemonOverrides& overrides) : config(c) {
    daemon = DaemonConfig::load(config);
    if (!overrides.source.empty()) daemon.source = overrides.source;
    if (!overrides.trajectory_out.empty()) daemon.trajectory_out = overrides.trajectory_out;
    if (!overrides.map_out.empty()) daemon.map_out = overrides.map_out;
    if (!overrides.groundtruth_out.empty()) daemon.groundtruth_out = overrides.groundtruth_out;
    if (!overrides.metrics_out.empty()) daemon.metrics_out = overrides.metrics_out;
    if (!overrides.session_in.empty()) daemon.session_in = overrides.session_in;
    if (!overrides.session_out.empty()) daemon.session_out = overrides.session_out;
    if (!overrides.lcm_url.empty()) config.set("lcm.url", overrides.lcm_url);
    checkOutputsAreDistinct();
    memory_governor = MemoryGovernor(daemon.memory_limit_mb);
    channels = ChannelConfig::load(config);
    tracking_config = TrackingConfig::load(config);
    filter_config = FilterConfig::load(config);
    mapping_config = MappingConfig::load(config);
    backend_config = BackendConfig::load(config);
    // Keyframe clouds are kept for the back end's corrections to move; the map is then made of
    // keyframes only, since frames between them could not follow a correction.
    if (!backend_config.enabled) mapping_config.keep_keyframe_clouds = false;
    if (mapping_config.keep_keyframe_clouds) mapping_config.keyframes_only = true;
    if (daemon.publish_frames) frame_publisher_config = LcmFramePublisherConfig::load(config);
    if (mapping_config.enabled) mapper = std::make_unique<Mapper>(mapping_config);
    if (!backend_config.enabled && !(daemon.session_in.empty() && daemon.session_out.empty())) {
      throw ConfigError(
          "sessions (--session-in, --session-out) need the back end: set "
          "backend.enabled=true");
    }
    if (backend_config.enabled) {
      if (!daemon.session_in.empty()) {
        // A loaded session brings its own vocabulary: its keyframes' words come from it.
        session = std::make_unique<Session>(loadSession(daemon.session_in));
        vocabulary = session->vocabulary;
      } else {
        try {
          vocabulary = loadVocabulary(backend_config);
        } catch (const VocabularyError& e) {
          throw ConfigError(std::string("backend.vocabulary_file: ") + e.what());
        }
      }
      backend = std::make_unique<BackendStage>(backend_config, vocabulary);
    }
    // The source reads its own sections (camera.*, capture.*, synthetic.*) now, so that every
    // configuration error surfaces before anything starts.
    source = createFrameSource(daemon.source, config);
    if (session) restoreSession();
    // Every section has been read: this is the configuration a saved session records (`config`
    // is the caller's and need not outlive the constructor).
    effective_config_yaml = config.effectiveYaml();
    if (overrides.wrap_source) source = overrides.wrap_source(std::move(source));
    removeStaleTemporaryFilesOfOutputs();
  }

  int run(ShutdownSignals& signals);
  /// Throws ConfigError when two outputs name the same file (one would overwrite the other).
  void checkOutputsAreDistinct() const;
  /// Removes what an earlier run killed during a save left behind ("<output>.tmp"), logged.
  void removeStaleTemporaryFilesOfOutputs() const;
  /// Opens the source and logs what will run; false (logged) when the source cannot be opened.
  bool openSource();
  /// The LCM bus with the command subscription running; null (logged) when it cannot be made.
  std::unique_ptr<LcmBus> startBus();
  void buildSteps(LcmBus& bus, DaemonPublishers& publishers);
  void wire(Pipeline& pipeline);
  /// Serves commands and the periodic status until the input ends or shutdown is requested;
  /// returns why it stopped.
  std::string controlLoop(ShutdownSignals& signals, LcmBus& bus, Pipeline& pipeline,
                          StatusBuilder& status_builder);
  void handleCommands(ShutdownSignals& signals);
  void handleMapCommand(const slamd::command_t& command);
  void publishStatus(LcmBus& bus, StatusBuilder& builder, Pipeline& pipeline,
                     const std::string& note);
  /// Reads the resident memory and hands the pressure level to the stages (logged on changes).
  void updateMemoryPressure();
  /// Fills `summary` from the stopped pipeline's counters and the steps.
  void summarize(const std::vector<StageStats>& stats, const FrameSourceStats& source_stats,
                 const LcmBus& bus, std::int64_t start_ns);
  void logSummary(const std::vector<StageStats>& stats, const FrameSourceStats& source_stats,
                  const LcmBus& bus) const;
  int writeOutputs();
  void finishBackend();
  /// Checks the loaded session against the camera and hands its back end and map to the
  /// stages; throws SessionError.
  void restoreSession();
  /// Writes the session (--session-out) from the stopped pipeline's state; false (logged) when
  /// it could not be written.
  bool saveSession(const std::string& dir);
  /// Writes a session of `snapshot`, the map and keyframe clouds through `save_map` (which
  /// writes them to the paths given); false (logged) when it could not be written.
  using SessionMapWriter =
      std::function<SavedMap(const std::string& map_path, const std::string& clouds_path)>;
  bool writeSession(const std::string& dir, const BackendSnapshot& snapshot,
                    const SessionMapWriter& save_map);
  /// SAVE_SESSION: asks the back-end and mapping threads for their parts...
  void startSessionSave(const slamd::command_t& command);
  /// ...and writes the session once both are in (called by the control loop).
  void progressSessionSave();
  /// False (logged) when the file could not be written.
  bool writeMetrics(const std::vector<StageStats>& stats);
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
        throw ConfigError(std::string("the ") + outputs[i].first + " and the " + outputs[j].first +
                          " outputs both name " + *outputs[i].second +
                          ": one would overwrite the other");
      }
    }
  }
}

void SlamDaemon::Impl::removeStaleTemporaryFilesOfOutputs() const {
  const std::vector<std::string> removed = removeStaleTemporaryFiles(
      {daemon.trajectory_out, daemon.map_out, daemon.map_save_path, daemon.groundtruth_out,
       daemon.metrics_out, mapping_config.snapshot_path,
       daemon.map_out.empty() ? "" : planes::planesPlyPathFor(daemon.map_out),
       daemon.map_save_path.empty() ? "" : planes::planesPlyPathFor(daemon.map_save_path)},
      daemon.save_dir, {".bt", ".ot", ".planes.ply"});
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
        steps->capture->pause();
        break;
      case slamd::command_t::RESUME:
        SLAMD_LOG_INFO(kLog) << "command RESUME";
        steps->capture->resume();
        break;
      case slamd::command_t::RESET:
        // Travels with the next packet: every stage resets when it reaches it (stage_steps.hpp).
        SLAMD_LOG_INFO(kLog) << "command RESET: tracking, filter and map start over";
        steps->capture->reset();
        break;
      case slamd::command_t::SHUTDOWN:
        SLAMD_LOG_INFO(kLog) << "command SHUTDOWN";
        signals.request();
        break;
      case slamd::command_t::SAVE_MAP:
      case slamd::command_t::PUBLISH_MAP:
        handleMapCommand(*command);
        break;
      case slamd::command_t::SAVE_SESSION:
        startSessionSave(*command);
        break;
      default:
        SLAMD_LOG_WARN(kLog) << "unknown command " << static_cast<int>(command->command)
                             << " ignored";
        break;
    }
  }
}

void SlamDaemon::Impl::handleMapCommand(const slamd::command_t& command) {
  if (!mapper) {
    SLAMD_LOG_WARN(kLog) << "map command ignored: mapping is disabled (mapping.enabled)";
    return;
  }
  MapRequest request;
  request.kind = command.command == slamd::command_t::SAVE_MAP ? MapRequest::Kind::kSave
                                                               : MapRequest::Kind::kPublish;
  request.path = !daemon.map_out.empty() ? daemon.map_out : daemon.map_save_path;
  if (request.kind == MapRequest::Kind::kSave && !command.argument.empty()) {
    // The file named by a peer on the network: confined to daemon.save_dir.
    std::string error;
    const std::optional<std::string> path =
        resolveCommandSavePath(command.argument, daemon.save_dir, error);
    if (!path) {
      commands_refused.fetch_add(1, std::memory_order_relaxed);
      SLAMD_LOG_WARN(kLog) << error;
      return;
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
}

void SlamDaemon::Impl::publishStatus(LcmBus& bus, StatusBuilder& builder, Pipeline& pipeline,
                                     const std::string& note) {
  StatusExtras extras;
  const FrameSourceStats source_stats = source->stats();
  extras.extra_errors["capture"] = source_stats.frames_skipped;
  extras.extra_drops["capture"] =
      source_stats.frames_dropped + steps->capture->stats().frames_dropped_paused;
  extras.extra_drops["vanishing"] = steps->vanishing ? steps->vanishing->stats() : 0;
  extras.tracking_state = steps->tracking->stats();
  const bool not_localized = steps->publish->stats().awaiting_map_frame.load();
  if (not_localized && extras.tracking_state != TrackingState::kLost &&
      extras.tracking_state != TrackingState::kNotInitialized) {
    extras.tracking_state = TrackingState::kNotLocalized;
  }
  if (steps->mapping) {
    const MappingStepStats map = steps->mapping->stats();
    extras.map_occupied_voxels = map.occupied_voxels;
    extras.map_total_voxels = map.leaf_voxels;
  }
  if (steps->backend) {
    const BackendStepStats back_end = steps->backend->stats();
    extras.num_keyframes = back_end.keyframes;
    extras.num_loops = back_end.loops;
    extras.num_relocalizations = back_end.relocalizations;
  }
  updateMemoryPressure();
  extras.memory_rss_mb = resident_mb;
  extras.memory_limit_mb = daemon.memory_limit_mb;
  extras.memory_pressure = memory_governor.level();
  extras.message = note;
  if (memory_governor.level() != MemoryPressure::kNone) {
    extras.message +=
        (extras.message.empty() ? "" : "; ") + std::string("memory ") +
        toString(memory_governor.level()) + " (" + std::to_string(static_cast<int>(resident_mb)) +
        " of " + std::to_string(daemon.memory_limit_mb) + " MB): fewer keyframes and kept clouds" +
        (memory_governor.level() == MemoryPressure::kOver ? ", coarser map far away" : "");
  }
  if (steps->filter && steps->filter->corridorMode().on.load(std::memory_order_relaxed)) {
    extras.message += (extras.message.empty() ? "" : "; ") +
                      std::string("corridor mode: features ran out, plane odometry fused (") +
                      std::to_string(steps->filter->corridorMode().fused.load()) +
                      " increments so far)";
  }
  if (not_localized) {
    extras.message += (extras.message.empty() ? "" : "; ") +
                      std::string(session ? "not yet localised in the loaded session's map: poses "
                                            "are in this run's own frame"
                                          : "not yet relocalised in the map after the loss: "
                                            "poses are relative to where the loss left them");
  }
  const std::string loss = steps->publish->stats().lossNote();
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
  bus.publishMessage(channels.status,
                     builder.build(wallClockUtime(), steadyNowNs(), pipeline.stats(),
                                   steps->publish->endToEnd().snapshot(), extras));
}

void SlamDaemon::Impl::updateMemoryPressure() {
  // Under pressure, memory the stages freed (released clouds, culled keyframes) goes back to
  // the system: glibc keeps freed heap pages otherwise, and the resident size would not show
  // what degrading saved.
  if (memory_governor.level() != MemoryPressure::kNone) malloc_trim(0);
  const std::optional<double> resident = residentMegabytes();
  if (!resident) return;
  resident_mb = *resident;
  summary.peak_resident_mb = std::max(summary.peak_resident_mb, resident_mb);
  const MemoryPressure before = memory_governor.level();
  const MemoryPressure now = memory_governor.update(resident_mb);
  memory_pressure.store(now, std::memory_order_relaxed);
  if (now == before) return;
  if (now > before) ++summary.memory_pressure_raised;
  SLAMD_LOG_WARN(kLog) << "memory: " << static_cast<int>(resident_mb) << " MB resident, limit "
                       << daemon.memory_limit_mb
                       << " MB (daemon.memory_limit_mb): " << toString(before) << " -> "
                       << toString(now)
                       << (now == MemoryPressure::kNone
                               ? ", no longer degrading"
                               : (now == MemoryPressure::kNear
                                      ? ", new keyframes culled harder and kept without images "
                                        "or clouds"
                                      : ", the kept clouds of older keyframes released and "
                                        "the map far from the camera made coarser"));
}

bool SlamDaemon::Impl::openSource() {
  try {
    source->open();
  } catch (const SourceError& e) {
    SLAMD_LOG_ERROR(kLog) << "cannot open source '" << daemon.source << "': " << e.what();
    return false;
  }
  SLAMD_LOG_INFO(kLog) << "source: " << source->description()
                       << (source->isLive() ? " (live: frames are dropped, never queued, when "
                                              "tracking falls behind)"
                                            : "");
  SLAMD_LOG_INFO(kLog)
      << "stages: capture, tracking (" << frontEndName(tracking_config.frontend) << "), filter ("
      << (filter_config.enabled ? (filter_config.vanishing_points ? "EKF + vanishing points"
                                                                  : "EKF, no vanishing points")
                                : "off: odometry chained")
      << "), publish, mapping ("
      << (mapper ? (mapping_config.keep_keyframe_clouds
                        ? "keyframes, moved by the back end's corrections"
                        : (mapping_config.keyframes_only ? "keyframes" : "every frame"))
                 : "off")
      << "), back end ("
      << (backend ? "loop closing, relocalisation, pose graph" : "off: backend.enabled is false")
      << ")";
  return true;
}

std::unique_ptr<LcmBus> SlamDaemon::Impl::startBus() {
  std::unique_ptr<LcmBus> bus;
  try {
    bus = std::make_unique<LcmBus>(channels.lcm_url);
  } catch (const std::exception& e) {
    SLAMD_LOG_ERROR(kLog) << e.what();
    return nullptr;
  }
  bus->subscribe<slamd::command_t>(channels.command,
                                   [this](const slamd::command_t& command, Utime) {
                                     if (!commands.tryPush(command)) {
                                       commands_dropped.fetch_add(1, std::memory_order_relaxed);
                                     }
                                   });
  bus->startHandling();
  return bus;
}

void SlamDaemon::Impl::buildSteps(LcmBus& bus, DaemonPublishers& publishers) {
  steps = std::make_unique<DaemonSteps>();
  DaemonSteps& s = *steps;
  std::function<void(const RgbdFrame&)> republish;
  if (daemon.publish_frames) {
    s.frame_publisher.emplace(bus.connection(), frame_publisher_config);
    republish = [&s](const RgbdFrame& frame) { s.frame_publisher->publish(frame); };
  }
  s.capture.emplace(*source, static_cast<std::int64_t>(daemon.heartbeat_period_s * 1e9),
                    std::move(republish));
  // The back end's keyframes near the newest go back to tracking, which re-uses them instead of
  // adding keyframes where the map already has the view (tracking.map_keyframes), and learns
  // whether its segment still awaits relocalisation.
  const bool send_map_keyframes = backend != nullptr;
  s.tracking.emplace(tracking_config, send_map_keyframes ? &s.map_keyframes : nullptr);
  if (session) {
    // The run's keyframes and segments continue the session's numbering.
    s.tracking->continueNumbering(backend->backend().nextKeyframeId(),
                                  backend->backend().nextSegment());
  }
  // Vanishing points: detected on their own thread in parallel with tracking, joined to the
  // tracked frame by the filter.
  const bool vanishing_point_thread =
      daemon.vanishing_point_thread && filter_config.enabled && filter_config.vanishing_points;
  if (vanishing_point_thread) s.vanishing.emplace(filter_config, s.vanishing_points);
  // Datasets played as fast as possible wait for every detection (repeatable runs); the generous
  // bound only guards against a detection that never comes (its frame failed on that thread).
  const auto wait = source->isLive() ? std::chrono::microseconds(static_cast<std::int64_t>(
                                           daemon.vanishing_point_wait_ms * 1000.0))
                                     : std::chrono::microseconds(2'000'000);
  // The corridor mode's plane segmentation: its own thread too, joined the same way.
  if (filter_config.enabled && filter_config.planes.enabled) s.planes.emplace(s.plane_segmentation);
  s.filter.emplace(filter_config, vanishing_point_thread ? &s.vanishing_points : nullptr, wait,
                   s.planes ? &s.plane_segmentation : nullptr);
  s.publish.emplace(publishers.direct, daemon.world_frame, daemon.camera_frame,
                    backend ? &s.pose_corrections : nullptr);
  if (session) s.publish->awaitMapFrame();
  if (mapper) {
    s.mapping.emplace(*mapper, mapping_config, publishers.mapping,
                      backend ? &s.map_corrections : nullptr, &map_requests);
    s.mapping->watchMemoryPressure(&memory_pressure);
    if (session) {
      s.mapping->useLoadedMap(backend_config.mode == BackendMode::kLocalize, session->map_path,
                              session->keyframe_clouds_path);
    }
  }
  if (backend) {
    s.backend.emplace(*backend, daemon.world_frame, publishers.backend, &s.pose_corrections,
                      mapper ? &s.map_corrections : nullptr,
                      send_map_keyframes ? &s.map_keyframes : nullptr);
    s.backend->watchMemoryPressure(&memory_pressure);
    s.backend->serveSnapshots(&snapshot_requests);
  }
}

// The back end's copy of a filtered frame: a frame that is not a keyframe loses its images (the
// back end uses only its odometry and pose), so a backlog behind a long optimisation costs about
// a kilobyte a frame instead of the images' megabytes.
namespace {
void slimBackendItem(EstimatedPacket& packet) {
  if (packet.odometry && !packet.odometry->is_keyframe) packet.frame.reset();
}
}  // namespace

// The wiring table: each stage, its input, the edge that feeds it (capacity, policy) and its
// thread's niceness. Datasets played as fast as possible wait for slow stages (nothing is lost,
// runs are repeatable); live sources must never be held up: their frames are dropped oldest-first
// (counted) and mapping skips to the newest frame. Mapping and the back end are off the
// latency-critical path: on a live (or paced) source their threads are niced, to use what the
// others leave. As fast as possible there is no latency to protect (every frame waits in a
// queue anyway), and a niced stage would only starve behind the others and slow the run. The back
// end needs every frame (a lost keyframe would break the graph) but must never hold up the filter,
// so on a live source its queue grows instead (a long optimisation is caught up afterwards); it
// holds the images of keyframes only.
void SlamDaemon::Impl::wire(Pipeline& pipeline) {
  DaemonSteps& s = *steps;
  const bool live = source->isLive();
  auto edge = [](int capacity, EdgePolicy policy) {
    return EdgeOptions{static_cast<std::size_t>(capacity), policy};
  };
  const EdgeOptions frames =
      edge(daemon.tracking_queue, live ? EdgePolicy::kDropOldest : EdgePolicy::kBackpressure);
  const EdgeOptions filter_in = edge(daemon.filter_queue, EdgePolicy::kBackpressure);
  const EdgeOptions publish_in = edge(daemon.publish_queue, EdgePolicy::kBackpressure);
  const EdgeOptions mapping_in =
      edge(daemon.mapping_queue, live ? EdgePolicy::kDrainToNewest : EdgePolicy::kBackpressure);
  const EdgeOptions backend_in =
      edge(daemon.backend_queue, live ? EdgePolicy::kGrowing : EdgePolicy::kBackpressure);
  // clang-format off
  //  stage        input      edge        step
  auto captured = pipeline.addSource<CapturePacket>(
      "capture",   [&s] { return s.capture->process(); });
  auto tracked = pipeline.addStage<CapturePacket, TrackedPacket>(
      "tracking",  captured,  frames,     body(*s.tracking));
  if (s.vanishing) pipeline.addSink<CapturePacket>(
      "vanishing", captured,  frames,     body(*s.vanishing));
  if (s.planes) pipeline.addSink<CapturePacket>(
      "planes",    captured,  frames,     body(*s.planes));
  auto estimated = pipeline.addStage<TrackedPacket, EstimatedPacket>(
      "filter",    tracked,   filter_in,  body(*s.filter));
  pipeline.addSink<EstimatedPacket>(
      "publish",   estimated, publish_in, body(*s.publish));
  if (s.mapping) pipeline.addSink<EstimatedPacket>(
      "mapping",   estimated, mapping_in, body(*s.mapping));
  if (s.backend) pipeline.addSink<EstimatedPacket>(
      "backend",   estimated, backend_in, body(*s.backend), slimBackendItem);
  //  thread options
  if (s.mapping && live) pipeline.setStageNice("mapping", daemon.mapping_nice);
  if (s.backend && live) pipeline.setStageNice("backend", daemon.backend_nice);
  // clang-format on
}

std::string SlamDaemon::Impl::controlLoop(ShutdownSignals& signals, LcmBus& bus, Pipeline& pipeline,
                                          StatusBuilder& status_builder) {
  SLAMD_LOG_INFO(kLog) << "running; LCM "
                       << (channels.lcm_url.empty() ? "<default URL>" : channels.lcm_url)
                       << ", poses on " << channels.pose << ", status on " << channels.status
                       << ", commands on " << channels.command;
  const auto status_period_ns = static_cast<std::int64_t>(daemon.status_period_s * 1e9);
  std::int64_t next_status_ns = steadyNowNs() + status_period_ns;
  while (true) {
    if (signals.waitFor(std::chrono::milliseconds(20))) {
      return signals.signalNumber() ? "signal " + std::to_string(signals.signalNumber())
                                    : "SHUTDOWN command";
    }
    handleCommands(signals);
    progressSessionSave();
    if (steadyNowNs() >= next_status_ns) {
      publishStatus(bus, status_builder, pipeline, steps->capture->paused() ? "paused" : "");
      next_status_ns += status_period_ns;
      end_to_end_by_minute.update(steadyNowNs(), steps->publish->endToEnd().snapshot());
    }
    if (pipeline.waitUntilFinished(std::chrono::steady_clock::now())) return "end of input";
  }
}

int SlamDaemon::Impl::run(ShutdownSignals& signals) {
  const std::int64_t start_ns = steadyNowNs();
  cv::setNumThreads(daemon.opencv_threads);
  if (!openSource()) return kExitSourceError;
  const std::unique_ptr<LcmBus> bus = startBus();
  if (!bus) return kExitFailure;
  DaemonPublishers publishers(*bus, channels);
  buildSteps(*bus, publishers);
  Pipeline pipeline(PipelineMode::kThreaded);
  wire(pipeline);
  // A daemon that starts near its memory limit degrades from the first keyframe on.
  updateMemoryPressure();

  StatusBuilder status_builder;
  publishers.relay.start();
  pipeline.start();
  end_to_end_by_minute.start(steadyNowNs(), steps->publish->endToEnd().snapshot());
  const std::string stop_reason = controlLoop(signals, *bus, pipeline, status_builder);
  SLAMD_LOG_INFO(kLog) << "stopping (" << stop_reason << "): draining queued frames";
  steps->capture->resume();
  const StopReport stop = pipeline.stop(
      std::chrono::milliseconds(static_cast<std::int64_t>(daemon.drain_deadline_s * 1000.0)));
  if (!stop.drained) {
    SLAMD_LOG_WARN(kLog) << "drain deadline passed; " << stop.discarded << " frames discarded";
  }
  source->close();
  // Mapping and the back end are joined: the relay publishes what they queued, so that a client
  // that acts on the "stopped" status (saving the map it rebuilt) has every message before it.
  // Later publishes on their lanes (map requests served below) go out directly.
  publishers.relay.stop();
  for (const auto& lane : publishers.relay.lanes()) {
    SLAMD_LOG_INFO(kLog) << "LCM relay lane " << lane->name() << ": " << lane->relayed()
                         << " messages published for it; its producer waited for room "
                         << lane->waited() << " times";
  }
  end_to_end_by_minute.finish(steadyNowNs(), steps->publish->endToEnd().snapshot());
  publishStatus(*bus, status_builder, pipeline, "stopped: " + stop_reason);
  bus->stopHandling();

  // The pipeline's threads are joined: their counters are final, and the control thread owns
  // the steps. Map requests that arrived during the drain are served here.
  if (steps->mapping) steps->mapping->serveRequests();
  const auto stats = pipeline.stats();
  const FrameSourceStats source_stats = source->stats();
  trajectory = std::move(steps->publish->trajectory());
  summarize(stats, source_stats, *bus, start_ns);
  logSummary(stats, source_stats, *bus);
  if (backend) finishBackend();
  // A SAVE_SESSION still waiting when the pipeline stopped is saved from the final state (the
  // threads that would have served it are gone).
  std::string command_session_dir;
  if (session_save) {
    command_session_dir = session_save->dir;
    session_save.reset();
  }
  const bool command_session_saved = command_session_dir.empty() ||
                                     command_session_dir == daemon.session_out ||
                                     saveSession(command_session_dir);
  const bool session_saved =
      (daemon.session_out.empty() || saveSession(daemon.session_out)) && command_session_saved;
  const bool metrics_written = daemon.metrics_out.empty() || writeMetrics(stats);
  const int outputs = writeOutputs();
  steps.reset();  // before the bus its frame publisher uses
  if (outputs != kExitOk) return outputs;
  return metrics_written && session_saved ? kExitOk : kExitOutputError;
}

void SlamDaemon::Impl::summarize(const std::vector<StageStats>& stats,
                                 const FrameSourceStats& source_stats, const LcmBus& bus,
                                 std::int64_t start_ns) {
  auto processed = [&stats](const std::string& stage) -> std::uint64_t {
    for (const auto& s : stats) {
      if (s.name == stage) return s.processed;
    }
    return 0;
  };
  summary.frames_captured = processed("capture");
  summary.frames_tracked = processed("tracking");
  summary.poses_published = processed("publish");
  if (mapper) {
    summary.frames_mapped = static_cast<std::uint64_t>(mapper->stats().frames_integrated);
    summary.map_blocks_merged = mapper->stats().far_map_blocks_merged;
  }
  for (const auto& stage : stats) {
    summary.errors += stage.errors;
    for (const auto& edge : stage.inputs) summary.drops += edge.dropped + edge.discarded;
    if (stage.name != "tracking") continue;
    for (const auto& edge : stage.inputs) {
      summary.frames_dropped_before_tracking += edge.dropped + edge.discarded;
    }
  }
  summary.errors += source_stats.frames_skipped;
  summary.drops += source_stats.frames_dropped + steps->capture->stats().frames_dropped_paused +
                   commands_dropped.load();
  summary.frames_behind_schedule = source_stats.frames_behind_schedule;
  summary.frames_over_rate = source_stats.frames_over_rate;
  const TrackingTally& tally = steps->publish->stats();
  summary.poses_tracked = tally.tracked.load();
  summary.poses_predicted = tally.predicted.load();
  summary.poses_lost = tally.lost.load();
  summary.poses_not_initialized = tally.not_initialized.load();
  summary.poses_not_localized = tally.not_localized.load();
  summary.not_localized_at_end = tally.awaiting_map_frame.load();
  summary.implausible_estimates = steps->tracking->implausibleEstimates();
  summary.prior_disagreements = steps->tracking->priorDisagreements();
  summary.dense_aligned_frames = steps->tracking->denseAlignedFrames();
  summary.map_keyframe_reuses = steps->tracking->mapKeyframeReuses();
  summary.relocalization_keyframes = steps->tracking->relocalizationKeyframes();
  summary.longest_loss_s = tally.longest_loss_s;
  summary.tracking_lost_at_end = tally.loss_start_utime.load() >= 0;
  summary.capture_gaps = tally.capture_gaps;
  summary.longest_capture_gap_s = tally.longest_capture_gap_s;
  summary.longest_resume_s = tally.longest_resume_s;
  summary.resumed_after_last_gap = tally.gap_return_utime < 0;
  summary.malformed_commands = bus.malformedCount(channels.command);
  summary.commands_refused = commands_refused.load();
  summary.duration_s = static_cast<double>(steadyNowNs() - start_ns) * 1e-9;
  const LatencySummary latency = steps->publish->endToEnd().summary();
  summary.end_to_end_p50_ms = latency.p50_ms;
  summary.end_to_end_p95_ms = latency.p95_ms;
  summary.end_to_end_p99_ms = latency.p99_ms;
  summary.end_to_end_max_ms = latency.max_ms;
  summary.end_to_end_by_minute = end_to_end_by_minute.windows();
  const CorridorModeStats& corridor = steps->filter->corridorMode();
  summary.corridor_mode_switched_on = corridor.switched_on.load();
  summary.corridor_mode_frames = corridor.frames.load();
  summary.plane_increments_fused = corridor.fused.load();
  summary.plane_increments_gated = corridor.gated.load();
  summary.plane_increments_unmatched = corridor.unmatched.load();
  summary.plane_increments_mean_nis = summary.plane_increments_fused > 0
                                          ? 1e-3 *
                                                static_cast<double>(corridor.nis_sum_milli.load()) /
                                                static_cast<double>(summary.plane_increments_fused)
                                          : 0.0;
  summary.plane_registrations_failed = corridor.registrations_failed.load();
  const EkfCounters ekf = steps->filter->ekfCounters();
  summary.direction_updates_accepted = ekf.updates_accepted;
  summary.direction_updates_gated = ekf.updates_gated;
  summary.direction_reanchors = ekf.reanchors;
  summary.direction_corrections_spread = ekf.corrections_spread;
}

void SlamDaemon::Impl::logSummary(const std::vector<StageStats>& stats,
                                  const FrameSourceStats& source_stats, const LcmBus& bus) const {
  if (summary.commands_refused > 0) {
    SLAMD_LOG_WARN(kLog) << "commands: " << summary.commands_refused
                         << " refused (SAVE_MAP outside daemon.save_dir " << daemon.save_dir << ")";
  }
  for (const auto& stage : stats) {
    std::uint64_t dropped = 0;
    for (const auto& edge : stage.inputs) dropped += edge.dropped + edge.discarded;
    SLAMD_LOG_INFO(kLog) << "stage " << stage.name << ": " << stage.processed << " processed"
                         << (stage.heartbeats > 0
                                 ? " (and " + std::to_string(stage.heartbeats) + " heartbeats)"
                                 : std::string())
                         << ", " << dropped << " dropped at its input, " << stage.errors
                         << " errors; time per item p50 " << stage.latency.p50_ms << " ms, p95 "
                         << stage.latency.p95_ms << " ms, p99 " << stage.latency.p99_ms
                         << " ms (CPU p50 " << stage.cpu.p50_ms << " ms, p99 " << stage.cpu.p99_ms
                         << " ms)";
  }
  SLAMD_LOG_INFO(kLog) << "frames: " << summary.frames_captured << " captured, "
                       << summary.frames_tracked << " tracked, " << summary.poses_published
                       << " poses published; " << summary.drops << " dropped, " << summary.errors
                       << " errors, " << bus.malformedTotal() << " malformed messages; "
                       << summary.duration_s << " s; capture-to-pose latency p50 "
                       << summary.end_to_end_p50_ms << " ms, p95 " << summary.end_to_end_p95_ms
                       << " ms, p99 " << summary.end_to_end_p99_ms << " ms, worst "
                       << summary.end_to_end_max_ms << " ms";
  if (summary.end_to_end_by_minute.size() > 1) {
    const auto worst =
        std::max_element(summary.end_to_end_by_minute.begin(), summary.end_to_end_by_minute.end(),
                         [](const LatencyWindow& a, const LatencyWindow& b) {
                           return a.latency.p99_ms < b.latency.p99_ms;
                         });
    SLAMD_LOG_INFO(kLog) << "capture-to-pose latency by minute: worst p99 " << worst->latency.p99_ms
                         << " ms in minute " << (worst - summary.end_to_end_by_minute.begin()) + 1
                         << " of " << summary.end_to_end_by_minute.size();
  }
  logTrackingSummary();
  if (summary.corridor_mode_switched_on > 0) {
    SLAMD_LOG_INFO(kLog) << "corridor mode: on " << summary.corridor_mode_switched_on << " times, "
                         << summary.corridor_mode_frames << " frames; plane increments "
                         << summary.plane_increments_fused << " fused (mean NIS "
                         << summary.plane_increments_mean_nis << "), "
                         << summary.plane_increments_gated << " gated, "
                         << summary.plane_registrations_failed << " registrations failed";
  }
  if (summary.direction_updates_accepted + summary.direction_updates_gated > 0) {
    SLAMD_LOG_INFO(kLog) << "filter: " << summary.direction_updates_accepted
                         << " direction updates accepted, " << summary.direction_updates_gated
                         << " gated, " << summary.direction_reanchors << " re-anchorings, "
                         << summary.direction_corrections_spread << " spread over frames";
  }
  logDropSummary(stats, source_stats);
  if (source_stats.clock_reanchors > 0) {
    SLAMD_LOG_WARN(kLog) << "source: its clock jumped and was re-anchored "
                         << source_stats.clock_reanchors << " times (see the capture warnings)";
  }
  const std::uint64_t late = steps->vanishing_points.late.load();
  const std::uint64_t overflowed = steps->vanishing_points.overflowed.load();
  if (late + overflowed > 0) {
    SLAMD_LOG_INFO(kLog) << "vanishing points: " << late
                         << " frames filtered without their detection (late or dropped), "
                         << overflowed << " detections overflowed";
  }
}

void SlamDaemon::Impl::logTrackingSummary() const {
  std::ostringstream line;
  line.precision(2);
  line << std::fixed << "tracking: " << summary.poses_tracked << " of " << summary.poses_published
       << " poses measured (" << summary.dense_aligned_frames << " by dense alignment), "
       << summary.poses_predicted << " predicted, " << summary.poses_lost << " lost, "
       << summary.poses_not_initialized << " before the first; longest loss "
       << summary.longest_loss_s << " s";
  if (summary.poses_published == 0) {
    SLAMD_LOG_WARN(kLog) << "tracking: no pose was published";
  } else if (summary.poses_tracked == 0) {
    SLAMD_LOG_WARN(kLog) << line.str() << "; NO POSE WAS MEASURED: tracking never started";
  } else if (summary.tracking_lost_at_end) {
    SLAMD_LOG_WARN(kLog) << line.str() << "; tracking LOST at the end ("
                         << steps->publish->stats().lossNote() << ")";
  } else if (summary.poses_predicted + summary.poses_lost > 0) {
    SLAMD_LOG_WARN(kLog) << line.str() << "; tracking OK at the end";
  } else {
    SLAMD_LOG_INFO(kLog) << line.str() << "; tracking OK throughout";
  }
  if (summary.implausible_estimates > 0) {
    SLAMD_LOG_WARN(kLog) << "tracking: " << summary.implausible_estimates
                         << " motion estimates vetoed as beyond the camera's motion limits "
                            "(filter.max_speed_mps, filter.max_angular_rate_radps), none published";
  }
  if (summary.prior_disagreements > 0) {
    SLAMD_LOG_INFO(kLog) << "tracking: " << summary.prior_disagreements
                         << " motion estimates rejected as too far from the constant-velocity "
                            "prediction (tracking.motion_prior_gate_sigma), then retried";
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
      line << "; " << dropped << " at the input of " << stage.name << " (" << dropReason(stage.name)
           << ")";
    }
  }
  const std::uint64_t dropped_paused = steps->capture->stats().frames_dropped_paused;
  if (dropped_paused > 0) line << "; " << dropped_paused << " frames read while paused";
  if (commands_dropped.load() > 0) {
    line << "; " << commands_dropped.load() << " commands (command queue full)";
  }
  SLAMD_LOG_WARN(kLog) << line.str();
}

bool SlamDaemon::Impl::writeMetrics(const std::vector<StageStats>& stats) {
  eval::JsonWriter json(true);
  json.beginObject();
  json.key("program").value("slamd");
  json.key("source").value(daemon.source);
  json.key("source_description").value(source->description());
  json.key("live").value(source->isLive());
  json.key("frames_captured").value(static_cast<std::int64_t>(summary.frames_captured));
  json.key("poses_published").value(static_cast<std::int64_t>(summary.poses_published));
  json.key("frames_mapped").value(static_cast<std::int64_t>(summary.frames_mapped));
  json.key("poses_tracked").value(static_cast<std::int64_t>(summary.poses_tracked));
  json.key("poses_predicted").value(static_cast<std::int64_t>(summary.poses_predicted));
  json.key("poses_lost").value(static_cast<std::int64_t>(summary.poses_lost));
  // Poses not (yet) in the map's frame: a loaded session's before the first relocalisation, and
  // those after a loss until the back end joined the new segment to the map.
  json.key("poses_not_localized").value(static_cast<std::int64_t>(summary.poses_not_localized));
  json.key("not_localized_at_end").value(summary.not_localized_at_end);
  json.key("implausible_estimates").value(static_cast<std::int64_t>(summary.implausible_estimates));
  json.key("prior_disagreements").value(static_cast<std::int64_t>(summary.prior_disagreements));
  json.key("dense_aligned_frames").value(static_cast<std::int64_t>(summary.dense_aligned_frames));
  json.key("map_keyframe_reuses").value(static_cast<std::int64_t>(summary.map_keyframe_reuses));
  json.key("relocalization_keyframes")
      .value(static_cast<std::int64_t>(summary.relocalization_keyframes));
  json.key("longest_loss_s").value(summary.longest_loss_s);
  json.key("tracking_lost_at_end").value(summary.tracking_lost_at_end);
  json.key("capture_gaps").value(static_cast<std::int64_t>(summary.capture_gaps));
  json.key("longest_capture_gap_s").value(summary.longest_capture_gap_s);
  json.key("longest_resume_s").value(summary.longest_resume_s);
  json.key("resumed_after_last_gap").value(summary.resumed_after_last_gap);
  json.key("frames_behind_schedule")
      .value(static_cast<std::int64_t>(summary.frames_behind_schedule));
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
  json.key("end_to_end_p50_ms").value(summary.end_to_end_p50_ms);
  json.key("end_to_end_p95_ms").value(summary.end_to_end_p95_ms);
  json.key("end_to_end_p99_ms").value(summary.end_to_end_p99_ms);
  json.key("end_to_end_max_ms").value(summary.end_to_end_max_ms);
  // Each minute's own frames: a long run's whole-run p99 hides a bad minute.
  json.key("end_to_end_by_minute").beginArray();
  for (const LatencyWindow& minute : summary.end_to_end_by_minute) {
    json.beginObject();
    json.key("start_s").value(minute.start_s);
    json.key("length_s").value(minute.length_s);
    json.key("frames").value(static_cast<std::int64_t>(minute.latency.count));
    json.key("p50_ms").value(minute.latency.p50_ms);
    json.key("p99_ms").value(minute.latency.p99_ms);
    json.key("max_ms").value(minute.latency.max_ms);
    json.endObject();
  }
  json.endArray();
  // The corridor mode (issue 23 item 4): how often features ran out, and what the planes gave.
  json.key("corridor_mode").beginObject();
  json.key("switched_on").value(static_cast<std::int64_t>(summary.corridor_mode_switched_on));
  json.key("frames").value(static_cast<std::int64_t>(summary.corridor_mode_frames));
  json.key("plane_increments_fused")
      .value(static_cast<std::int64_t>(summary.plane_increments_fused));
  json.key("plane_increments_gated")
      .value(static_cast<std::int64_t>(summary.plane_increments_gated));
  json.key("plane_increments_unmatched")
      .value(static_cast<std::int64_t>(summary.plane_increments_unmatched));
  json.key("plane_increments_mean_nis").value(summary.plane_increments_mean_nis);
  json.key("plane_registrations_failed")
      .value(static_cast<std::int64_t>(summary.plane_registrations_failed));
  json.endObject();
  json.key("filter").beginObject();
  json.key("direction_updates_accepted").value(summary.direction_updates_accepted);
  json.key("direction_updates_gated").value(summary.direction_updates_gated);
  json.key("reanchors").value(summary.direction_reanchors);
  json.key("corrections_spread").value(summary.direction_corrections_spread);
  json.endObject();
  // Resident memory at the status messages, and how often the memory limit made slamd degrade.
  json.key("memory").beginObject();
  json.key("limit_mb").value(daemon.memory_limit_mb);
  json.key("peak_resident_mb").value(summary.peak_resident_mb);
  json.key("pressure_raised").value(static_cast<std::int64_t>(summary.memory_pressure_raised));
  json.endObject();
  if (backend) {
    json.key("backend").beginObject();
    json.key("keyframes").value(summary.keyframes);
    // Keyframe rate against the distance and time of the estimated trajectory (issue 22: new
    // keyframes come from novelty, not from every frame of a turn).
    const double distance_m = pathLengthM(trajectory);
    const double duration_s = durationS(trajectory);
    json.key("distance_travelled_m").value(distance_m);
    json.key("metres_per_keyframe")
        .value(summary.keyframes > 0 ? distance_m / static_cast<double>(summary.keyframes) : 0.0);
    json.key("keyframes_per_s")
        .value(duration_s > 0 ? static_cast<double>(summary.keyframes) / duration_s : 0.0);
    json.key("culled_keyframes").value(summary.culled_keyframes);
    json.key("keyframe_bytes").value(summary.keyframe_bytes);
    json.key("bytes_per_keyframe")
        .value(summary.keyframes > 0 ? summary.keyframe_bytes / summary.keyframes : 0);
    json.key("loops").value(summary.loops);
    json.key("relocalizations").value(summary.relocalizations);
    json.key("optimizations").value(summary.optimizations);
    json.key("max_optimization_ms").value(summary.max_optimization_ms);
    json.key("background_optimizations").value(summary.background_optimizations);
    json.key("max_background_optimization_ms").value(summary.max_background_optimization_ms);
    json.endObject();
  }
  if (session) {
    // The loaded session (issue 25): when this run was localised in its map.
    json.key("session").beginObject();
    json.key("loaded").value(session->generation_path);
    json.key("mode").value(backendModeName(backend_config.mode));
    json.key("frames_before_localization").value(summary.frames_before_localization);
    json.key("poses_not_localized").value(static_cast<std::int64_t>(summary.poses_not_localized));
    json.endObject();
  }
  if (mapper) {
    // Kept keyframe clouds and how the map followed the back end's corrections (issue 24).
    const MapperStats& map_stats = mapper->stats();
    json.key("mapping").beginObject();
    json.key("frames_integrated").value(map_stats.frames_integrated);
    json.key("keyframe_clouds").value(map_stats.keyframe_clouds);
    json.key("keyframe_cloud_bytes").value(map_stats.keyframe_cloud_bytes);
    json.key("keyframe_clouds_refused").value(map_stats.keyframe_clouds_refused);
    json.key("keyframe_clouds_released").value(map_stats.keyframe_clouds_released);
    json.key("octree_bytes").value(static_cast<std::int64_t>(mapper->memoryBytes()));
    json.key("keyframes_moved").value(map_stats.keyframes_moved);
    json.key("keyframes_taken_out").value(map_stats.keyframes_taken_out);
    json.key("corrections_caught_up").value(map_stats.corrections_caught_up);
    json.key("far_map_coarsenings").value(map_stats.far_map_coarsenings);
    json.key("far_map_blocks_merged").value(map_stats.far_map_blocks_merged);
    if (steps && steps->mapping) {
      json.key("catch_up_cycles_deferred").value(steps->mapping->stats().catch_up_cycles_deferred);
    }
    json.endObject();
  }
  json.key("stages").beginObject();
  for (const auto& stage : stats) {
    json.key(stage.name).beginObject();
    json.key("processed").value(static_cast<std::int64_t>(stage.processed));
    json.key("heartbeats").value(static_cast<std::int64_t>(stage.heartbeats));
    json.key("p50_ms").value(stage.latency.p50_ms);
    json.key("p95_ms").value(stage.latency.p95_ms);
    json.key("p99_ms").value(stage.latency.p99_ms);
    json.key("cpu_p50_ms").value(stage.cpu.p50_ms);
    json.key("cpu_p99_ms").value(stage.cpu.p99_ms);
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

void SlamDaemon::Impl::finishBackend() {
  backend->finish();
  const BackendStageStats& stats = backend->stats();
  summary.keyframes = stats.keyframes;
  summary.loops = stats.loops;
  summary.relocalizations = stats.relocalizations;
  summary.optimizations = stats.optimizations;
  summary.max_optimization_ms = stats.max_optimization_ms;
  summary.culled_keyframes = stats.culled_keyframes;
  summary.frames_before_localization = stats.frames_before_localization;
  if (session) {
    if (stats.frames_before_localization >= 0) {
      SLAMD_LOG_INFO(kLog) << "session: localised in the loaded map at frame "
                           << stats.frames_before_localization << " of this run";
    } else {
      SLAMD_LOG_WARN(kLog) << "session: this run was never localised in the loaded map; its "
                              "trajectory is in its own frame (its first camera pose)";
    }
  }
  summary.keyframe_bytes = stats.keyframe_bytes;
  summary.background_optimizations = stats.background_optimizations;
  summary.max_background_optimization_ms = stats.max_background_optimization_ms;
  SLAMD_LOG_INFO(kLog) << "back end: " << stats.keyframes << " keyframes ("
                       << stats.culled_keyframes << " redundant ones culled; "
                       << (stats.keyframes > 0 ? stats.keyframe_bytes / stats.keyframes / 1024 : 0)
                       << " KiB each), " << stats.loops << " loops, " << stats.relocalizations
                       << " relocalisations, " << stats.optimizations
                       << " optimisations (longest in the back-end thread "
                       << stats.max_optimization_ms << " ms; " << stats.background_optimizations
                       << " of the whole graph in the background, longest "
                       << stats.max_background_optimization_ms << " ms)";
  // The written trajectory and map take the final optimised poses, including corrections that
  // arrived after the publish and mapping threads had finished.
  trajectory = backend->optimizedTrajectory();
  if (!mapper) return;
  if (session && stats.frames_before_localization < 0) {
    // Never placed in the loaded map: the keyframes held for it must not go in at poses of this
    // run's own frame.
    for (const std::int64_t id : mapper->keptKeyframeIds()) {
      if (id >= first_run_keyframe_id) mapper->forgetKeyframe(id);
    }
    SLAMD_LOG_WARN(kLog) << "session: this run's keyframes were left out of the map (never "
                            "localised in it)";
    return;
  }
  if (stats.optimizations > 0) {
    for (const std::int64_t id : backend->backend().culledKeyframeIds()) {
      mapper->forgetKeyframe(id);
    }
    std::vector<std::pair<std::int64_t, SE3>> keyframe_poses;
    for (const std::int64_t id : backend->backend().graph().nodeIds()) {
      keyframe_poses.emplace_back(id, backend->backend().pose(id));
    }
    mapper->correctKeyframePoses(keyframe_poses);
  }
  {
    // Keyframes still queued (new ones, or moves the mapping thread had no time for) go in now.
    const CatchUpResult caught_up = mapper->catchUp(std::numeric_limits<double>::infinity());
    SLAMD_LOG_INFO(kLog) << "final map: " << caught_up.keyframes_added << " keyframes put in and "
                         << caught_up.keyframes_moved << " moved to their optimised poses in "
                         << caught_up.seconds << " s (" << mapper->stats().keyframes_moved
                         << " moves during the run)";
  }
}

void SlamDaemon::Impl::restoreSession() {
  const std::optional<CameraIntrinsics> camera = source->intrinsics();
  if (camera) {
    const std::string mismatch = cameraMismatch(session->info.camera, *camera);
    if (!mismatch.empty()) {
      throw SessionError("session " + session->generation_path + " was made with another camera (" +
                         mismatch + "); its map cannot be localised in with " + daemon.source);
    }
  }
  // The loaded keyframes may move (slam mode) only when the map can follow them: every one of
  // their clouds is kept again (or there is no map to follow).
  bool map_follows = true;
  std::size_t clouds_restored = 0;
  if (mapper && !session->map_path.empty()) {
    const MapFileResult loaded = mapper->loadMap(session->map_path);
    if (!loaded.ok) throw SessionError("session map " + session->map_path + ": " + loaded.error);
    std::vector<KeyframeCloudRecord> clouds;
    if (!session->keyframe_clouds_path.empty()) {
      std::string error;
      if (!readKeyframeCloudRecords(session->keyframe_clouds_path, clouds, &error)) {
        throw SessionError(error);
      }
    }
    const std::size_t saved_clouds = clouds.size();
    if (mapping_config.keep_keyframe_clouds && saved_clouds > 0) {
      clouds_restored = mapper->restoreKeyframeClouds(std::move(clouds));
    }
    map_follows = saved_clouds > 0 && clouds_restored == saved_clouds &&
                  saved_clouds >= session->backend.keyframes.size();
  }
  const bool fix_loaded_keyframes = backend_config.mode == BackendMode::kLocalize || !map_follows;
  backend->restore(std::make_shared<const BackendSnapshot>(std::move(session->backend)),
                   fix_loaded_keyframes);
  first_run_keyframe_id = backend->backend().nextKeyframeId();
  SLAMD_LOG_INFO(kLog) << "session " << session->generation_path << " loaded ("
                       << session->info.keyframes << " keyframes, " << session->info.landmarks
                       << " landmarks, " << session->info.map_voxels << " map voxels, "
                       << clouds_restored << " keyframe clouds; made by "
                       << session->info.created_by << "); mode "
                       << backendModeName(backend_config.mode) << ", loaded keyframes "
                       << (fix_loaded_keyframes ? "fixed" : "free to move with the map")
                       << "; poses are TRACKING_NOT_LOCALIZED until the first relocalisation";
  session->backend = BackendSnapshot();  // moved into the back end
}

bool SlamDaemon::Impl::saveSession(const std::string& dir) {
  const auto start = std::chrono::steady_clock::now();
  const BackendSnapshot snapshot = backend->backend().snapshot();
  const bool saved =
      writeSession(dir, snapshot, [this](const std::string& map_path, const std::string& clouds) {
        return saveMapForSession(*mapper, map_path, clouds);
      });
  if (saved) {
    SLAMD_LOG_INFO(kLog)
        << "session written to " << dir << " in "
        << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s";
  }
  return saved;
}

bool SlamDaemon::Impl::writeSession(const std::string& dir, const BackendSnapshot& snapshot,
                                    const SessionMapWriter& save_map) {
  try {
    SessionWriter writer(dir);
    writer.writeBackend(snapshot);
    writer.writeVocabulary(*vocabulary);
    SessionInfo info;
    info.created_utime = wallClockUtime();
    info.created_by = std::string("slamd ") + SLAMD_VERSION_STRING;
    if (const std::optional<CameraIntrinsics> camera = source->intrinsics()) {
      info.camera = *camera;
    } else if (!snapshot.keyframes.empty()) {
      info.camera = snapshot.keyframes.front()->intrinsics;
    }
    summarizeSnapshot(snapshot, info);
    if (mapper) {
      const SavedMap map =
          save_map(writer.pathFor(kSessionMapFile), writer.pathFor(kSessionKeyframeCloudsFile));
      if (!map.file.ok) throw SessionError("cannot write the session's map: " + map.file.error);
      if (!map.clouds_error.empty()) {
        throw SessionError("cannot write the session's keyframe clouds: " + map.clouds_error);
      }
      writer.addFile(kSessionMapFile);
      if (map.clouds_written) writer.addFile(kSessionKeyframeCloudsFile);
      info.map_voxels = map.voxels;
      info.map_min_m = map.min_m;
      info.map_max_m = map.max_m;
    }
    writer.writeText(kSessionConfigFile, effective_config_yaml);
    writer.commit(info);
    SLAMD_LOG_INFO(kLog) << "session: " << info.keyframes << " keyframes, " << info.landmarks
                         << " landmarks, " << info.map_voxels << " map voxels in "
                         << writer.generationPath();
    return true;
  } catch (const SessionError& e) {
    SLAMD_LOG_ERROR(kLog) << "session not saved: " << e.what();
    return false;
  }
}

void SlamDaemon::Impl::startSessionSave(const slamd::command_t& command) {
  if (!backend) {
    SLAMD_LOG_WARN(kLog) << "SAVE_SESSION ignored: the back end is off (backend.enabled)";
    return;
  }
  if (session_save) {
    SLAMD_LOG_WARN(kLog) << "SAVE_SESSION ignored: a session is being saved to "
                         << session_save->dir;
    return;
  }
  std::string dir = daemon.session_out.empty()
                        ? (std::filesystem::path(daemon.save_dir) / "session").string()
                        : daemon.session_out;
  if (!command.argument.empty()) {
    // The folder named by a peer on the network: confined to daemon.save_dir.
    std::string error;
    const std::optional<std::string> path =
        resolveCommandSessionPath(command.argument, daemon.save_dir, error);
    if (!path) {
      commands_refused.fetch_add(1, std::memory_order_relaxed);
      SLAMD_LOG_WARN(kLog) << error;
      return;
    }
    dir = *path;
  }
  SessionSave save;
  save.dir = dir;
  save.started_ns = steadyNowNs();
  auto snapshot = std::make_shared<std::promise<std::shared_ptr<const BackendSnapshot>>>();
  save.snapshot = snapshot->get_future();
  if (!snapshot_requests.tryPush(std::move(snapshot))) {
    SLAMD_LOG_WARN(kLog) << "SAVE_SESSION dropped: too many pending snapshot requests";
    return;
  }
  if (mapper) {
    // The mapping thread writes the map next to the session; it joins the generation once the
    // back end's snapshot is in.
    std::error_code ignored;
    std::filesystem::create_directories(dir, ignored);
    save.map_path = (std::filesystem::path(dir) / "map.pending.ot").string();
    save.clouds_path = (std::filesystem::path(dir) / "keyframe_clouds.pending.bin").string();
    MapRequest request;
    request.kind = MapRequest::Kind::kSave;
    request.path = save.map_path;
    request.clouds_path = save.clouds_path;
    request.saved = std::make_shared<std::promise<SavedMap>>();
    save.map = request.saved->get_future();
    if (!map_requests.tryPush(std::move(request))) {
      SLAMD_LOG_WARN(kLog) << "SAVE_SESSION dropped: too many pending map requests";
      return;
    }
  }
  SLAMD_LOG_INFO(kLog) << "command SAVE_SESSION " << dir;
  session_save = std::move(save);
}

void SlamDaemon::Impl::progressSessionSave() {
  if (!session_save) return;
  const auto ready = [](const auto& future) {
    return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
  };
  if (!ready(session_save->snapshot) || (session_save->map.valid() && !ready(session_save->map))) {
    return;
  }
  SessionSave save = std::move(*session_save);
  session_save.reset();
  const std::shared_ptr<const BackendSnapshot> snapshot = save.snapshot.get();
  std::optional<SavedMap> map;
  if (save.map.valid()) map = save.map.get();
  // The files the mapping thread wrote join the generation.
  const auto moveInto = [](const std::string& from, const std::string& to, std::string& error) {
    std::error_code failed;
    std::filesystem::rename(from, to, failed);
    if (failed) error = "cannot move " + from + " to " + to + ": " + failed.message();
  };
  const bool saved = writeSession(save.dir, *snapshot,
                                  [&](const std::string& map_path, const std::string& clouds_path) {
                                    SavedMap moved = *map;
                                    if (moved.file.ok) {
                                      moveInto(save.map_path, map_path, moved.file.error);
                                      moved.file.ok = moved.file.error.empty();
                                    }
                                    if (moved.file.ok && moved.clouds_written) {
                                      moveInto(save.clouds_path, clouds_path, moved.clouds_error);
                                      moved.clouds_written = moved.clouds_error.empty();
                                    }
                                    return moved;
                                  });
  if (saved) {
    SLAMD_LOG_INFO(kLog) << "SAVE_SESSION: session written to " << save.dir << " in "
                         << static_cast<double>(steadyNowNs() - save.started_ns) * 1e-9 << " s";
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
      // The planes beside the map (the pipeline has stopped: this thread owns the plane map).
      if (steps && steps->mapping && mapping_config.planes_enabled) {
        const MapFileResult planes_saved = steps->mapping->savePlaneMap(daemon.map_out);
        if (planes_saved.ok) {
          SLAMD_LOG_INFO(kLog) << "planes: " << steps->mapping->planeMap().worldPlanes().size()
                               << " planes written to " << planes_saved.path;
        } else {
          SLAMD_LOG_ERROR(kLog) << "planes not saved: " << planes_saved.error;
          exit_code = kExitOutputError;
        }
      }
    }
  }
  return exit_code;
}

}  // namespace slamd
