#pragma once
// SlamDaemon: the slamd program. Wires the capture, tracking, filter, publishing, mapping and
// back-end stages with the pipeline runner (one thread each, bounded lock-free queues between
// them),
// speaks LCM to the rest of the robot, and runs until the source ends, a SHUTDOWN command arrives
// or the process is signalled.
//
//   Config config = Config::fromFile("config/tum_fr1.yaml");
//   DaemonOverrides overrides;  overrides.source = "tum:/data/fr1_xyz";
//   SlamDaemon daemon(config, overrides);       // reads every module's configuration
//   reportConfig(config, "slamd");
//   return daemon.run(signals);                 // exit code
//
// Structure: each stage is a step class (stage_steps.hpp: capture, tracking, vanishing points,
// filter, publish, mapping, back end) with no threads inside; slam_daemon.cpp builds the steps and
// wires them in one table (stage, input, edge capacity and policy, thread niceness).
//
// Threads: one per stage, owned by the pipeline (the back end with backend.enabled; vanishing-point
// detection with daemon.vanishing_point_thread and the filter on; plane segmentation for the
// corridor mode with filter.planes.enabled and the filter on); the LCM bus has its own receive
// thread (commands only: it pushes them into a queue); the calling thread runs the control loop
// (commands, 1 Hz status) and, after the pipeline has stopped, writes outputs. RESET travels
// through the queues with the frames, so every stage resets at the same point of the stream.

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "slamd/common/config.hpp"
#include "slamd/common/latency_histogram.hpp"
#include "slamd/common/shutdown_signals.hpp"

namespace slamd {

class FrameSource;

/// Command-line values that take precedence over the configuration file.
struct DaemonOverrides {
  std::string source;           ///< --source
  std::string lcm_url;          ///< --lcm-url
  std::string trajectory_out;   ///< --trajectory-out
  std::string map_out;          ///< --map-out
  std::string groundtruth_out;  ///< --groundtruth-out
  std::string metrics_out;      ///< --metrics-out
  std::string session_in;       ///< --session-in
  std::string session_out;      ///< --session-out
  /// Wraps the source the configuration names (tests: fault injection such as a camera that
  /// drops out); empty = none.
  std::function<std::unique_ptr<FrameSource>(std::unique_ptr<FrameSource>)> wrap_source;
};

/// What a finished run did (logged at exit, returned for tests).
struct DaemonSummary {
  std::uint64_t frames_captured = 0;  ///< frames delivered by the source (heartbeats excluded)
  std::uint64_t frames_tracked = 0;   ///< frames the tracking stage processed
  std::uint64_t poses_published = 0;
  std::uint64_t frames_mapped = 0;
  // Published poses by tracking state: measured (OK or RELOCALIZED), predicted without a
  // measurement, lost, and before the first pose.
  std::uint64_t poses_tracked = 0;
  std::uint64_t poses_predicted = 0;
  std::uint64_t poses_lost = 0;
  std::uint64_t poses_not_initialized = 0;
  /// Poses published TRACKING_NOT_LOCALIZED: a session was loaded and the run had not yet been
  /// relocalised in its map, or after a loss the back end had not yet joined the new tracking
  /// segment to the map (counted in the states above too).
  std::uint64_t poses_not_localized = 0;
  bool not_localized_at_end = false;  ///< the last pose was published TRACKING_NOT_LOCALIZED
  /// With --session-in: frames tracked before the one whose keyframe localised the run in the
  /// loaded map (BackendStageStats::frames_before_localization); -1 when never localised.
  std::int64_t frames_before_localization = -1;
  /// Motion estimates vetoed as beyond the camera's motion limits (then retried or predicted).
  std::uint64_t implausible_estimates = 0;
  std::uint64_t prior_disagreements = 0;  ///< estimates rejected by the motion prior's gate
  /// Poses measured by dense alignment where features failed (part of poses_tracked).
  std::uint64_t dense_aligned_frames = 0;
  /// Frames that took one of the back end's keyframes as reference where tracking would have
  /// made a keyframe (tracking.map_keyframes).
  std::uint64_t map_keyframe_reuses = 0;
  /// Keyframes made early because the segment awaited relocalisation in the back end's map
  /// (tracking.relocalization_keyframe_*).
  std::uint64_t relocalization_keyframes = 0;
  double longest_loss_s = 0.0;        ///< longest run of predicted or lost poses, frame time
  bool tracking_lost_at_end = false;  ///< the last published pose was not measured
  // Gaps in the camera's frames (more than 0.5 s of capture time between two poses: a camera
  // that stopped and came back) and the time from the first frame back to a measured pose.
  std::uint64_t capture_gaps = 0;
  double longest_capture_gap_s = 0.0;
  double longest_resume_s = 0.0;
  bool resumed_after_last_gap = true;  ///< false: no pose was measured after the last gap
  // Why frames were dropped (each also counted in `drops`).
  std::uint64_t frames_behind_schedule = 0;  ///< passed over by a real-time source running late
  std::uint64_t frames_over_rate = 0;        ///< received faster than a camera sends (lcm: sources)
  std::uint64_t frames_dropped_before_tracking = 0;  ///< tracking's input queue was full
  std::uint64_t drops = 0;
  std::uint64_t errors = 0;
  std::uint64_t malformed_commands = 0;
  std::uint64_t commands_refused = 0;  ///< SAVE_MAP naming a file outside daemon.save_dir
  // Back end (zero when backend.enabled is false).
  std::int64_t keyframes = 0;         ///< in the graph at the end
  std::int64_t culled_keyframes = 0;  ///< redundant keyframes removed
  std::int64_t keyframe_bytes = 0;    ///< held by the back end's keyframes at the end
  std::int64_t loops = 0;
  std::int64_t relocalizations = 0;
  std::int64_t optimizations = 0;
  double max_optimization_ms = 0.0;           ///< in the back-end thread
  std::int64_t background_optimizations = 0;  ///< whole-graph ones on their own thread
  double max_background_optimization_ms = 0.0;
  // Memory (daemon.memory_limit_mb): the largest resident size seen at a status message, and
  // how many times the pressure level went up.
  double peak_resident_mb = 0.0;
  std::uint64_t memory_pressure_raised = 0;
  std::int64_t map_blocks_merged = 0;  ///< far map made coarser over the limit (Mapper stats)
  double duration_s = 0.0;
  double end_to_end_p50_ms = 0.0;
  double end_to_end_p95_ms = 0.0;
  double end_to_end_p99_ms = 0.0;
  double end_to_end_max_ms = 0.0;  ///< the worst frame's capture-to-pose latency
  // The corridor mode (filter.planes): times it came on, frames filtered with it on, and the
  // plane increments fused, gated (too far from tracking's), measured over another interval, and
  // the fused ones' mean NIS; plane registrations that failed.
  std::uint64_t corridor_mode_switched_on = 0;
  std::uint64_t corridor_mode_frames = 0;
  std::uint64_t plane_increments_fused = 0;
  std::uint64_t plane_increments_gated = 0;
  std::uint64_t plane_increments_unmatched = 0;
  double plane_increments_mean_nis = 0.0;
  std::uint64_t plane_registrations_failed = 0;
  // The EKF's direction updates (vanishing points and plane axes) since the last RESET: accepted,
  // gated, re-anchorings after an odometry jump, and updates spread over several frames
  // (filter.max_correction_rate_degps).
  std::int64_t direction_updates_accepted = 0;
  std::int64_t direction_updates_gated = 0;
  std::int64_t direction_reanchors = 0;
  std::int64_t direction_corrections_spread = 0;
  /// Capture-to-pose latency of each minute of the run (the last one may be shorter).
  std::vector<LatencyWindow> end_to_end_by_minute;
};

class SlamDaemon {
 public:
  /// Reads every module's configuration; throws ConfigError naming the bad key.
  SlamDaemon(Config& config, const DaemonOverrides& overrides);
  ~SlamDaemon();
  SlamDaemon(const SlamDaemon&) = delete;
  SlamDaemon& operator=(const SlamDaemon&) = delete;

  /// Runs to completion. Returns kExitOk, kExitSourceError (source cannot be opened),
  /// kExitOutputError (an output could not be written) or kExitFailure.
  int run(ShutdownSignals& signals);

  const DaemonSummary& summary() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace slamd
