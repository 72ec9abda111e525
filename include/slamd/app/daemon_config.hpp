#pragma once
// DaemonConfig: the daemon's own options (keys `daemon.*`); each stage reads its own section
// (tracking.*, filter.*, mapping.*, capture.*, synthetic.*, channels.*, lcm.*).

#include <string>

#include "slamd/common/config.hpp"

namespace slamd {

struct DaemonConfig {
  /// daemon.source (string, default "synthetic:room"): tum:DIR | openni2[:URI] | oni:FILE |
  /// lcm:CHANNEL | synthetic:SCENE; --source overrides it.
  std::string source = "synthetic:room";
  /// daemon.trajectory_out (path, default ""): TUM trajectory written at exit (--trajectory-out).
  std::string trajectory_out;
  /// daemon.map_out (path .bt or .ot, default ""): map written at exit (--map-out).
  std::string map_out;
  /// daemon.groundtruth_out (path, default ""): the source's ground truth (TUM folders, synthetic
  /// worlds) written at exit in TUM format, next to the trajectory (--groundtruth-out).
  std::string groundtruth_out;
  /// daemon.metrics_out (path, default ""): run metrics as JSON at exit (frames, rate, drops,
  /// per-stage and capture-to-pose latency percentiles), for benchmarks (--metrics-out).
  std::string metrics_out;
  /// daemon.status_period_s (double, default 1, 0.05..60, s): SLAMD_STATUS publication period.
  double status_period_s = 1.0;
  /// daemon.drain_deadline_s (double, default 5, 0..600, s): at shutdown, how long the stages may
  /// take to finish queued frames before the rest is discarded (and counted).
  double drain_deadline_s = 5.0;
  /// daemon.heartbeat_period_s (double, default 0.2, 0.01..10, s): with no frame for this long the
  /// capture thread sends a heartbeat so later stages can serve commands.
  double heartbeat_period_s = 0.2;
  /// daemon.tracking_queue (int, default 1, 1..1000): frames waiting for tracking. Live and
  /// real-time sources drop the oldest when it is full (1: tracking always gets the newest frame,
  /// the lowest latency); datasets played as fast as possible wait.
  int tracking_queue = 1;
  /// daemon.filter_queue (int, default 8, 1..1000): tracked frames waiting for the filter (never
  /// dropped).
  int filter_queue = 8;
  /// daemon.publish_queue (int, default 16, 1..1000): poses waiting for publication (never dropped).
  int publish_queue = 16;
  /// daemon.mapping_queue (int, default 2, 1..1000): frames waiting for mapping; live runs skip to
  /// the newest (the map only needs recent views), datasets played as fast as possible wait.
  int mapping_queue = 2;
  /// daemon.backend_queue (int, default 600, 1..100000): filtered frames waiting for the back
  /// end (never dropped: a lost keyframe would break the graph). The back end only does real work
  /// on keyframes, but a long optimisation must not hold up the filter: the queue absorbs it.
  int backend_queue = 600;
  /// daemon.vanishing_point_thread (bool, default true): detect vanishing points on a thread of
  /// their own, in parallel with tracking, instead of on the filter thread after it: takes the
  /// detection (a few ms) off the capture-to-pose path. Only when the filter uses vanishing points.
  bool vanishing_point_thread = true;
  /// daemon.vanishing_point_wait_ms (double, default 5, 0..1000, ms): live and real-time sources
  /// only: how long the filter waits for a frame's detection when it is not ready yet; a later
  /// detection is skipped and counted. Datasets played as fast as possible always wait.
  double vanishing_point_wait_ms = 5.0;
  /// daemon.publish_frames (bool, default false): republish every processed frame (channel and
  /// encodings: capture.publish.*), so lcm-logger captures the input and a log can be replayed
  /// into slamd.
  bool publish_frames = false;
  /// mapping.enabled (bool, default true): run the mapping stage (voxel filter + OctoMap).
  bool mapping_enabled = true;
  /// mapping.keyframes_only (bool, default false): integrate only keyframes instead of every
  /// tracked frame (less CPU, sparser free space).
  bool map_keyframes_only = false;
  /// daemon.map_save_path (path, default "slamd_map.bt"): where SAVE_MAP writes when the command
  /// names no file and no --map-out was given.
  std::string map_save_path = "slamd_map.bt";
  /// daemon.save_dir (folder, default "maps", relative to the working directory; created when
  /// first needed): the only folder a SAVE_MAP command received over LCM may name a file in
  /// (see command_save_path.hpp). Empty: commands may not name files at all.
  std::string save_dir = "maps";
  /// daemon.mapping_nice (int, default 10, 0..19): niceness of the mapping thread. Mapping is off
  /// the capture-to-pose path, so it gets the CPU the latency-critical stages leave.
  int mapping_nice = 10;
  /// daemon.backend_nice (int, default 5, 0..19): niceness of the back-end thread (loop closing
  /// and pose-graph optimisation are off the capture-to-pose path).
  int backend_nice = 5;
  /// daemon.opencv_threads (int, default 0, 0..64): OpenCV's own worker threads. 0 runs every
  /// OpenCV call on the stage thread that makes it: the pipeline already keeps the cores busy
  /// with one thread per stage, and a hidden pool would compete with them for the same cores.
  int opencv_threads = 0;
  /// daemon.world_frame / daemon.camera_frame (strings): frame names in published poses.
  std::string world_frame = "world";
  std::string camera_frame = "camera";

  static DaemonConfig load(Config& config);
};

}  // namespace slamd
