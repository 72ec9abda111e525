#pragma once
// The daemon's stages as steps: one class per pipeline stage, all of the same small shape
//
//   process(packet) -> what the stage passes on (nothing for a sink)
//   reset()         -> forget the state (the RESET command)
//   stats()         -> what the stage reports in the status message and the exit summary
//
// with no threads and no LCM inside, so that a test can drive a whole chain by hand. The daemon
// (slam_daemon.cpp) gives each step a thread and connects them with the Pipeline's queues; what a
// step publishes goes through DaemonPublisher (LCM in the daemon, a recorder in tests).
//
// RESET travels with the data. The control thread calls CaptureStep::reset(), which starts a new
// reset epoch; every packet carries the epoch it was captured in (CaptureStep stamps it, every
// step copies it to what it passes on). A step resets when the first packet of a newer epoch
// reaches it, before processing that packet. The pipeline's edges keep order, so every packet
// captured before the RESET reaches a step before that step's reset (and is processed, or dropped
// by a drop-oldest edge like any other frame), never after it. Because the epoch rides on every
// packet, frames and heartbeats alike, an edge that drops packets cannot drop the reset: the next
// packet that gets through carries it. A packet of an older epoch arriving after a reset (which
// FIFO edges never deliver) is refused and counted, never processed.
//
// Corrections from the back end travel beside the stream, so they carry the back end's epoch
// too: a correction computed before a reset is dropped, one computed after it waits until the
// receiving step has reset as well.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <unordered_map>

#include "slamd/app/backend_stage.hpp"
#include "slamd/app/packets.hpp"
#include "slamd/app/pose_estimator.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/common/latency_histogram.hpp"
#include "slamd/common/memory_pressure.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/mapping/mapper.hpp"
#include "slamd/pipeline/pipeline.hpp"
#include "slamd/pipeline/spsc_queue.hpp"
#include "slamd/pipeline/wake_signal.hpp"
#include "slamd/planes/plane_map.hpp"
#include "slamd/tracking/visual_odometry.hpp"

namespace slamd {

/// Everything the steps publish to the rest of the robot (LCM in the daemon). Called from the
/// steps' threads: implementations must be thread-safe.
class DaemonPublisher {
 public:
  virtual ~DaemonPublisher() = default;
  /// The published pose (slamd and bot_core pose channels).
  virtual void publishPose(const PoseEstimate& pose) = 0;
  virtual void publishOdometry(const OdometryResult& odometry) = 0;
  virtual void publishVanishingPoint(Utime utime, const VanishingPointReport& report) = 0;
  virtual void publishKeyframes(const KeyframeTrajectory& trajectory) = 0;
  virtual void publishMapUpdate(const MapUpdate& update) = 0;
  virtual void publishFullMap(const FullMap& map) = 0;
  /// The map's planes (mapping.planes.enabled).
  virtual void publishPlaneMap(const planes::PlaneMapSnapshot& plane_map) = 0;
};

/// One packet as a step saw it, for tests (see StepBase::setTrace).
struct StepTraceEntry {
  Utime utime = -1;               ///< the frame's capture time; -1 for a heartbeat
  std::uint64_t reset_epoch = 0;  ///< the packet's epoch
  std::uint64_t resets = 0;       ///< resets the step had done when it processed the packet
};

/// The reset-epoch bookkeeping every step downstream of capture shares.
class StepBase {
 public:
  virtual ~StepBase() = default;
  virtual void reset() = 0;

  /// Epoch of the packets the step processes now, and how many resets it did.
  std::uint64_t resetEpoch() const { return epoch_; }
  std::uint64_t resets() const { return resets_; }
  /// Packets refused because they were captured before the step's last reset.
  std::uint64_t stalePackets() const { return stale_; }
  /// Called for every packet the step processes, after the reset it caused if any (tests).
  void setTrace(std::function<void(const StepTraceEntry&)> trace) { trace_ = std::move(trace); }

 protected:
  /// Resets the step when `epoch` is newer than its own. Returns false for a stale packet (older
  /// epoch), which the caller must not process.
  bool enter(std::uint64_t epoch, const RgbdFramePtr& frame);
  /// The same for a packet that carries its capture time but no images (-1: a heartbeat).
  bool enter(std::uint64_t epoch, Utime utime);

 private:
  std::uint64_t epoch_ = 0;
  std::uint64_t resets_ = 0;
  std::uint64_t stale_ = 0;
  std::function<void(const StepTraceEntry&)> trace_;
};

/// Items of a side queue (back-end corrections) taken in the receiving step's reset epoch:
/// older ones are dropped, newer ones are kept until the step has reset too.
template <typename T>
class EpochInbox {
 public:
  explicit EpochInbox(SpscQueue<T>* queue) : queue_(queue) {}

  /// Passes every waiting item of `epoch` to `take`, oldest first.
  template <typename Take>
  void take(std::uint64_t epoch, Take&& take) {
    while (!ahead_.empty() && ahead_.front().reset_epoch <= epoch) {
      if (ahead_.front().reset_epoch == epoch) take(std::move(ahead_.front()));
      ahead_.pop_front();
    }
    if (queue_ == nullptr) return;
    while (auto item = queue_->tryPop()) {
      if (item->reset_epoch < epoch) continue;  // computed before this step's reset
      if (item->reset_epoch > epoch || !ahead_.empty()) {
        ahead_.push_back(std::move(*item));
      } else {
        take(std::move(*item));
      }
    }
  }

  void clear() { ahead_.clear(); }

 private:
  SpscQueue<T>* queue_;
  std::deque<T> ahead_;
};

// --- capture ---------------------------------------------------------------------------------

struct CaptureStepStats {
  std::uint64_t frames_dropped_paused = 0;  ///< live frames read and thrown away while paused
  std::uint64_t reset_epoch = 0;
};

/// Reads the source; emits a frame, or a heartbeat when none came for a heartbeat period (paused,
/// a live source that went quiet) so that downstream stages still serve their requests.
/// pause/resume/reset/stats may be called from any thread (the control loop).
class CaptureStep {
 public:
  /// `republish` (may be empty) is given every captured frame (daemon.publish_frames).
  CaptureStep(FrameSource& source, std::int64_t heartbeat_period_ns,
              std::function<void(const RgbdFrame&)> republish);

  SourceStep<CapturePacket> process();

  /// Starts a new reset epoch: the next packet carries it, and each stage resets on it.
  void reset() { reset_epoch_.fetch_add(1, std::memory_order_acq_rel); }
  void pause() { paused_.store(true, std::memory_order_release); }
  /// Ends a pause (also on shutdown, so that a paused recording does not hold the drain up).
  void resume();
  bool paused() const { return paused_.load(std::memory_order_acquire); }
  CaptureStepStats stats() const;

 private:
  SourceStep<CapturePacket> emit(RgbdFramePtr frame);

  FrameSource& source_;
  const bool live_;
  const std::int64_t heartbeat_period_ns_;
  std::function<void(const RgbdFrame&)> republish_;
  std::int64_t last_emit_ns_;
  std::atomic<bool> paused_{false};
  WakeSignal resume_signal_;
  std::atomic<std::uint64_t> frames_dropped_paused_{0};
  std::atomic<std::uint64_t> reset_epoch_{0};
};

// --- tracking --------------------------------------------------------------------------------

/// The back end's keyframes near its newest one, for tracking (VisualOdometry::setMapKeyframes).
struct MapKeyframesPacket {
  MapKeyframes keyframes;
  std::uint64_t reset_epoch = 0;
};

/// Visual odometry on every frame.
class TrackingStep : public StepBase {
 public:
  /// `map_keyframes`: the back end's keyframes near the newest (null without a back end).
  explicit TrackingStep(const TrackingConfig& config,
                        SpscQueue<MapKeyframesPacket>* map_keyframes = nullptr)
      : odometry_(config), map_keyframes_(map_keyframes) {}

  std::optional<TrackedPacket> process(CapturePacket packet);
  void reset() override {
    odometry_.reset();
    map_keyframes_.clear();
  }
  /// VisualOdometry::continueNumbering (before the pipeline starts).
  void continueNumbering(std::int64_t next_keyframe_id, std::int64_t next_segment) {
    odometry_.continueNumbering(next_keyframe_id, next_segment);
  }
  /// The latest frame's tracking state (any thread).
  TrackingState stats() const {
    return static_cast<TrackingState>(tracking_state_.load(std::memory_order_relaxed));
  }
  /// Motion estimates vetoed by the motion limits so far (any thread).
  std::uint64_t implausibleEstimates() const {
    return implausible_estimates_.load(std::memory_order_relaxed);
  }
  /// Motion estimates rejected as too far from the constant-velocity prediction (any thread).
  std::uint64_t priorDisagreements() const {
    return prior_disagreements_.load(std::memory_order_relaxed);
  }
  /// Frames measured by dense alignment because features failed, so far (any thread).
  std::uint64_t denseAlignedFrames() const {
    return dense_aligned_frames_.load(std::memory_order_relaxed);
  }
  /// Frames that took one of the map's keyframes as reference instead of making a keyframe
  /// (any thread).
  std::uint64_t mapKeyframeReuses() const {
    return map_keyframe_reuses_.load(std::memory_order_relaxed);
  }
  /// Keyframes made early for the back end to relocalise the segment (any thread).
  std::uint64_t relocalizationKeyframes() const {
    return relocalization_keyframes_.load(std::memory_order_relaxed);
  }

 private:
  VisualOdometry odometry_;
  EpochInbox<MapKeyframesPacket> map_keyframes_;
  std::atomic<int> tracking_state_{static_cast<int>(TrackingState::kNotInitialized)};
  std::atomic<std::uint64_t> implausible_estimates_{0};
  std::atomic<std::uint64_t> prior_disagreements_{0};
  std::atomic<std::uint64_t> dense_aligned_frames_{0};
  std::atomic<std::uint64_t> map_keyframe_reuses_{0};
  std::atomic<std::uint64_t> relocalization_keyframes_{0};
};

// --- steps parallel to tracking (vanishing points, plane segmentation) --------------------------

/// A step parallel to tracking (producer) -> the filter step (consumer): one result per frame, in
/// frame order.
template <typename Packet>
struct FrameResultChannel {
  SpscQueue<Packet> queue{256};
  WakeSignal ready;
  std::atomic<std::uint64_t> late{0};        ///< results the filter gave up waiting for
  std::atomic<std::uint64_t> overflowed{0};  ///< results that found the queue full

  void push(Packet packet) {
    if (!queue.tryPush(std::move(packet))) overflowed.fetch_add(1, std::memory_order_relaxed);
    ready.notify();
  }
};

/// The filter step's end of a FrameResultChannel: joins a frame's result to the tracked frame by
/// capture time (Packet::utime).
template <typename Packet>
class FrameResultJoin {
 public:
  FrameResultJoin(FrameResultChannel<Packet>* channel, std::chrono::microseconds wait)
      : channel_(channel), wait_(wait) {}

  bool connected() const { return channel_ != nullptr; }
  /// The result of the frame captured at `utime`, waiting up to the wait for it; nullopt when it
  /// is late, or was dropped (a result of a later frame is already there), counted as late.
  std::optional<Packet> take(Utime utime) {
    FrameResultChannel<Packet>& channel = *channel_;
    const auto deadline = std::chrono::steady_clock::now() + wait_;
    while (true) {
      const auto seen = channel.ready.epoch();
      if (!held_) held_ = channel.queue.tryPop();
      // Results of frames tracking skipped are passed over.
      while (held_ && held_->utime < utime) held_ = channel.queue.tryPop();
      if (held_ && held_->utime == utime) {
        std::optional<Packet> result = std::move(held_);
        held_.reset();
        return result;
      }
      if (held_) break;  // the next result is of a later frame: this frame's was dropped
      if (!channel.ready.waitFor(seen, deadline)) break;
    }
    channel.late.fetch_add(1, std::memory_order_relaxed);
    return std::nullopt;
  }

 private:
  FrameResultChannel<Packet>* channel_;
  std::chrono::microseconds wait_;
  std::optional<Packet> held_;  ///< a result of a later frame
};

using VanishingPointChannel = FrameResultChannel<VanishingPointPacket>;

/// Detects each frame's vanishing point in parallel with tracking; the filter step joins it to
/// the tracked frame by capture time.
class VanishingPointStep : public StepBase {
 public:
  VanishingPointStep(const FilterConfig& config, VanishingPointChannel& channel)
      : config_(config), channel_(channel) {}

  void process(CapturePacket packet);
  /// The detector keeps nothing from one frame to the next: nothing to forget.
  void reset() override {}
  /// Detections lost: late at the filter or overflowed (any thread).
  std::uint64_t stats() const {
    return channel_.late.load(std::memory_order_relaxed) +
           channel_.overflowed.load(std::memory_order_relaxed);
  }

 private:
  FilterConfig config_;
  VanishingPointChannel& channel_;
  std::optional<VanishingPointDetector> detector_;  ///< created at the first frame (intrinsics)
};

/// Plane segmentation (the corridor mode, filter.planes.*) -> filter step; the filter step sets
/// corridor_mode, the plane-segmentation step reads it.
struct PlaneSegmentationChannel : FrameResultChannel<PlaneSegmentationPacket> {
  std::atomic<bool> corridor_mode{false};
};

/// While the filter has the corridor mode on, segments each frame into planes (paper 000) for the
/// filter's plane ICP; otherwise passes frames through unsegmented (the filter still gets one
/// packet per frame, so it never waits for nothing). In parallel with tracking: the segmentation,
/// the mode's costly part, adds no time to the capture-to-pose path beyond the join.
class PlaneSegmentationStep : public StepBase {
 public:
  PlaneSegmentationStep(PlaneSegmentationChannel& channel) : channel_(channel) {}

  void process(CapturePacket packet);
  /// The segmenter keeps nothing from one frame to the next.
  void reset() override {}

 private:
  PlaneSegmentationChannel& channel_;
  planes::PlaneSegmenter segmenter_;
};

// --- filter ----------------------------------------------------------------------------------

/// The pose filter (PoseEstimator), fed the vanishing point of each frame when the vanishing-
/// point step runs, and its planes when the plane-segmentation step runs.
class FilterStep : public StepBase {
 public:
  /// `vanishing_points`: null when the filter detects them itself (or not at all);
  /// `result_wait`: how long to wait for a frame's detection or planes;
  /// `plane_segmentation`: null without the corridor mode.
  FilterStep(const FilterConfig& config, VanishingPointChannel* vanishing_points,
             std::chrono::microseconds result_wait,
             PlaneSegmentationChannel* plane_segmentation = nullptr);

  std::optional<EstimatedPacket> process(TrackedPacket packet);
  void reset() override { estimator_.reset(); }
  /// The corridor mode's counts (any thread).
  const CorridorModeStats& corridorMode() const { return estimator_.corridorMode(); }
  EkfCounters ekfCounters() const { return estimator_.ekfCounters(); }

 private:
  PoseEstimator estimator_;
  FrameResultJoin<VanishingPointPacket> vanishing_points_;
  FrameResultJoin<PlaneSegmentationPacket> plane_segmentation_;
  PlaneSegmentationChannel* plane_channel_;
};

// --- publish ---------------------------------------------------------------------------------

/// The back end's correction as the publish step needs it.
struct PoseCorrection {
  SE3 T_world_uncorrected = SE3::Identity();
  bool relocalized = false;  ///< mark the next published pose TRACKING_RELOCALIZED
  /// The newest keyframe is in the map's frame (false while its tracking segment, the first of a
  /// run in a loaded session or one after a loss, has not been relocalised into the map).
  bool map_frame_known = true;
  std::uint64_t reset_epoch = 0;
  std::int64_t segment = -1;  ///< the newest keyframe's tracking segment
};

/// Published poses by tracking state, and the current loss. Written by the publish step; the
/// atomics may be read from any thread (status), the rest after the publish thread joined.
struct TrackingTally {
  std::atomic<std::uint64_t> tracked{0};  ///< measured: OK or RELOCALIZED
  std::atomic<std::uint64_t> predicted{0};
  std::atomic<std::uint64_t> lost{0};
  std::atomic<std::uint64_t> not_initialized{0};
  /// Of the poses with an estimate, those published TRACKING_NOT_LOCALIZED (a loaded session's
  /// map, or after a loss the map of the run so far, not yet relocalised into); counted in the
  /// states above too.
  std::atomic<std::uint64_t> not_localized{0};
  /// The latest pose was not yet in the map's frame (any thread).
  std::atomic<bool> awaiting_map_frame{false};
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

  void record(TrackingState state, Utime utime);
  /// "tracking lost for 1.2 s (36 frames)" during a loss, else empty.
  std::string lossNote() const;
};

/// Applies the back end's correction to each filtered pose and publishes it (pose, odometry,
/// vanishing point); keeps the published trajectory and the capture-to-pose latency.
///
/// With a back end (`corrections` given), a pose is in the map's frame only while its tracking
/// segment is: the run's first segment is, unless a session was loaded (awaitMapFrame); a segment
/// started after a loss is not until a correction says the back end joined it to the map
/// (relocalisation, or a loop). Until then poses are published TRACKING_NOT_LOCALIZED: tracking
/// works, but the pose is relative to where the loss left it.
class PublishStep : public StepBase {
 public:
  PublishStep(DaemonPublisher& publisher, std::string world_frame, std::string camera_frame,
              SpscQueue<PoseCorrection>* corrections);

  void process(EstimatedPacket packet);
  void reset() override;
  /// A session was loaded: poses are TRACKING_NOT_LOCALIZED until a correction puts the newest
  /// keyframe in the map's frame (PoseCorrection::map_frame_known), and again after a reset.
  /// Before the pipeline starts.
  void awaitMapFrame();
  const TrackingTally& stats() const { return tally_; }
  /// Capture-to-publication latency (any thread).
  const LatencyHistogram& endToEnd() const { return end_to_end_; }
  /// Published poses that are estimates (not lost); read after the publish thread joined.
  Trajectory& trajectory() { return trajectory_; }

 private:
  DaemonPublisher& publisher_;
  std::string world_frame_;
  std::string camera_frame_;
  EpochInbox<PoseCorrection> corrections_;
  SE3 correction_ = SE3::Identity();
  bool corrected_ = false;
  bool relocalized_ = false;
  bool localizes_in_loaded_map_ = false;
  bool awaiting_map_frame_ = false;
  bool with_back_end_ = false;
  /// Tracking's current segment, and the newest one a correction put in the map's frame (-1:
  /// none yet).
  std::int64_t current_segment_ = -1;
  std::int64_t newest_segment_in_map_ = -1;
  TrackingTally tally_;
  LatencyHistogram end_to_end_;
  Trajectory trajectory_;
};

// --- mapping ---------------------------------------------------------------------------------

/// A map written for a session, with what the session's manifest says of it.
struct SavedMap {
  MapFileResult file;
  /// The kept keyframe clouds were written (none are kept: nothing written, not an error).
  bool clouds_written = false;
  std::string clouds_error;                         ///< a sentence when they could not be written
  std::int64_t voxels = 0;                          ///< leaves of the tree
  Eigen::Vector3d min_m = Eigen::Vector3d::Zero();  ///< extent, map frame (zero when empty)
  Eigen::Vector3d max_m = Eigen::Vector3d::Zero();
};

/// Mapper::saveMap(map_path), the kept keyframe clouds to clouds_path (when any are kept), and
/// the map's size and extent (by the thread that owns the mapper).
SavedMap saveMapForSession(Mapper& mapper, const std::string& map_path,
                           const std::string& clouds_path);

/// A request from the control loop to the mapping step, which owns the map while running.
struct MapRequest {
  enum class Kind { kSave, kPublish };
  Kind kind = Kind::kSave;
  std::string path;  ///< kSave: .bt or .ot
  /// kSave for a session (SAVE_SESSION): the keyframe clouds go to clouds_path, the result to
  /// `saved` (the control loop waits on it).
  std::string clouds_path;
  std::shared_ptr<std::promise<SavedMap>> saved;
};

/// A request from the control loop to the back-end step: the back end's snapshot (a session
/// being saved while running).
using SnapshotRequest = std::shared_ptr<std::promise<std::shared_ptr<const BackendSnapshot>>>;

/// A back-end correction as the mapping step receives it.
struct MapCorrection {
  BackendCorrection correction;
  std::uint64_t reset_epoch = 0;
};

struct MappingStepStats {
  std::int64_t leaf_voxels = 0;
  std::int64_t occupied_voxels = 0;      ///< counted every few seconds
  std::int64_t keyframes_segmented = 0;  ///< keyframes whose planes went into the plane map
  std::int64_t pixels_snapped = 0;       ///< keyframe pixels moved onto their plane
  /// Cycles that left waiting catch-up steps to the next frame (no room left in their budget).
  std::int64_t catch_up_cycles_deferred = 0;
};

/// Integrates each tracked frame (or keyframe) into the map at its corrected pose, moves the
/// keyframes the back end's corrections move (within mapping.keyframe_step_budget_ms per frame),
/// serves SAVE_MAP / PUBLISH_MAP and publishes the map.
/// With mapping.planes.enabled it also segments each keyframe into planes (here, so that one
/// thread owns the plane map), fuses them into the plane map, which follows the same corrections
/// and culls as the keyframes' clouds, snaps the keyframe's depth onto its planes before the
/// keyframe goes into the OctoMap (mapping.planes.snap_depth), publishes the plane map with the
/// map's updates when it changed, with every full map and on PUBLISH_MAP, and writes it beside
/// the map on SAVE_MAP (planes::planesPlyPathFor).
class MappingStep : public StepBase {
 public:
  MappingStep(Mapper& mapper, const MappingConfig& config, DaemonPublisher& publisher,
              SpscQueue<MapCorrection>* corrections, SpscQueue<MapRequest>* requests);

  /// Throws when a frame could not be mapped (the pipeline counts it against this stage).
  void process(const EstimatedPacket& packet);
  void reset() override;
  /// The mapper holds a loaded session's map, read from `map_path`, and its keyframe clouds, from
  /// `clouds_path` (empty: none) (before the pipeline starts). Until a correction puts the run in
  /// the map's frame (BackendCorrection::map_frame_known), keyframes are held out of the map
  /// (Mapper::holdKeyframe) and other frames skipped; the correction's poses then put the held
  /// keyframes in. With `frozen` (backend.mode=localize) nothing goes in: the map stays as
  /// loaded. RESET reads both again (an empty map, logged, when that generation of the session
  /// has been replaced since).
  void useLoadedMap(bool frozen, std::string map_path, std::string clouds_path);
  /// Serves the waiting map requests (also called by the control thread after the stop).
  void serveRequests();
  MappingStepStats stats() const;
  /// Writes the plane map as PLY polygons beside the map file `map_path` (mapping thread, or the
  /// control thread after the stop). Not ok, with a sentence, when the planes are off.
  MapFileResult savePlaneMap(const std::string& map_path);
  /// The plane map (the mapping thread's; the control thread's after the stop).
  planes::PlaneMap& planeMap() { return plane_map_; }
  /// The level the mapper degrades by (read every cycle; set by the control thread). Under
  /// kOver, the kept clouds of all but the newest kKeptCloudsOverTheLimit keyframes are
  /// released, and the map far from the camera is made coarser (Mapper::coarsenFarMap) every
  /// kCoarseningPeriodNs at most.
  void watchMemoryPressure(const std::atomic<MemoryPressure>* pressure) {
    memory_pressure_ = pressure;
  }
  static constexpr std::size_t kKeptCloudsOverTheLimit = 20;
  static constexpr std::int64_t kCoarseningPeriodNs = 5'000'000'000;
  /// How often the voxels are counted for the status channel, at most (a walk of the map).
  static constexpr std::int64_t kVoxelCountPeriodNs = 5'000'000'000;

 private:
  void applyCorrections();
  /// Catch-up steps in what is left of the cycle's budget (see stage_steps.cpp).
  void catchUp(std::int64_t cycle_start_ns, bool keyframe_mapped);
  /// Forgets the kept clouds and planes of keyframes a correction no longer lists (culled by the
  /// back end).
  void forgetCulledKeyframes(const std::vector<std::pair<std::int64_t, SE3>>& keyframe_poses);
  /// Segments a keyframe, adds its planes to the plane map and returns the frame to map: the
  /// keyframe with its depth snapped onto its planes (mapping.planes.snap_depth), or `frame`.
  const RgbdFrame& addKeyframePlanes(const RgbdFrame& frame, const SE3& T_world_camera,
                                     std::int64_t keyframe_id);
  void publishPlaneMap();
  void publishOutputs(const MapperOutputs& outputs);
  /// Under kOver: makes the map far from the camera (T_world_camera) coarser, when due.
  void coarsenFarMap(const SE3& T_world_camera);

  Mapper& mapper_;
  bool keyframes_only_;
  std::string frame_id_;
  bool planes_enabled_;
  bool snap_depth_;
  double snap_sigmas_;
  planes::PlaneSegmenter segmenter_;
  planes::PlaneMap plane_map_;
  bool plane_map_changed_ = false;  ///< since it was last published
  cv::Mat snapped_depth_m_;         ///< scratch: the keyframe's depth snapped onto its planes
  RgbdFrame snapped_frame_;         ///< scratch: the keyframe with that depth
  double step_budget_s_;            ///< per frame, for moving keyframes a correction moved
  DaemonPublisher& publisher_;
  EpochInbox<MapCorrection> corrections_;
  SpscQueue<MapRequest>* requests_;
  std::int64_t next_voxel_count_ns_ = 0;
  std::int64_t next_coarsening_ns_ = 0;
  bool deferred_last_cycle_ = false;  ///< the last cycle left waiting catch-up steps undone
  std::atomic<std::int64_t> catch_up_cycles_deferred_{0};  ///< cycles that did so
  /// The back end's correction: uncorrected (filter) world -> corrected world.
  SE3 T_world_uncorrected_ = SE3::Identity();
  bool snapshot_failing_ = false;    ///< the last periodic snapshot failed
  bool map_frozen_ = false;          ///< a loaded map that frames never change
  std::string loaded_map_path_;      ///< the loaded session's map file, for RESET
  std::string loaded_clouds_path_;   ///< and its keyframe clouds
  bool awaiting_map_frame_ = false;  ///< frames are not yet in the loaded map's frame
  std::atomic<std::int64_t> leaf_voxels_{0};
  std::atomic<std::int64_t> occupied_voxels_{0};
  std::atomic<std::int64_t> keyframes_segmented_{0};
  std::atomic<std::int64_t> pixels_snapped_{0};
  const std::atomic<MemoryPressure>* memory_pressure_ = nullptr;
};

// --- back end --------------------------------------------------------------------------------

struct BackendStepStats {
  std::int32_t keyframes = 0;
  std::int32_t loops = 0;
  std::int32_t relocalizations = 0;
};

/// Runs the back end (BackendStage) on every filtered frame; hands each correction to the
/// publish and mapping steps and publishes the optimised keyframes.
class BackendStep : public StepBase {
 public:
  /// `map_corrections`: null when mapping is off. `map_keyframes`: to tracking, after each
  /// keyframe (null: not sent).
  BackendStep(BackendStage& backend, std::string world_frame, DaemonPublisher& publisher,
              SpscQueue<PoseCorrection>* pose_corrections,
              SpscQueue<MapCorrection>* map_corrections,
              SpscQueue<MapKeyframesPacket>* map_keyframes = nullptr);

  void process(const EstimatedPacket& packet);
  void reset() override {
    backend_.reset();
    map_keyframes_anchor_id_ = -1;
  }
  /// Snapshot requests from the control loop, served on every packet (heartbeats too).
  void serveSnapshots(SpscQueue<SnapshotRequest>* requests) { snapshot_requests_ = requests; }
  /// Counts for the status message (any thread).
  BackendStepStats stats() const;
  /// The level the back end degrades by (read on every packet; set by the control thread).
  void watchMemoryPressure(const std::atomic<MemoryPressure>* pressure) {
    memory_pressure_ = pressure;
  }

 private:
  BackendStage& backend_;
  std::string world_frame_;
  DaemonPublisher& publisher_;
  SpscQueue<PoseCorrection>* pose_corrections_;
  SpscQueue<MapCorrection>* map_corrections_;
  SpscQueue<MapKeyframesPacket>* map_keyframes_;
  std::int64_t map_keyframes_anchor_id_ = -1;  ///< the newest keyframe they were sent for
  SpscQueue<SnapshotRequest>* snapshot_requests_ = nullptr;
  std::atomic<std::int32_t> keyframes_{0};
  std::atomic<std::int32_t> loops_{0};
  std::atomic<std::int32_t> relocalizations_{0};
  const std::atomic<MemoryPressure>* memory_pressure_ = nullptr;
};

}  // namespace slamd
