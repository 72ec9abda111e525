#include "slamd/app/daemon_config.hpp"

namespace slamd {

const ConfigSchema<DaemonConfig>& DaemonConfig::schema() {
  using C = DaemonConfig;
  static const auto table =
      ConfigSchema<C>("daemon")
          .text("source", &C::source,
                "tum:DIR | openni2[:URI] | oni:FILE | lcm:CHANNEL | synthetic:SCENE (--source); "
                "not empty")
          .text("trajectory_out", &C::trajectory_out,
                "TUM trajectory written at exit (--trajectory-out); empty = none")
          .text("map_out", &C::map_out, "map (.bt or .ot) written at exit (--map-out)")
          .text("session_in", &C::session_in,
                "session folder to load at start (--session-in): its map, keyframes and pose "
                "graph; the run localises in it (backend.mode); empty = none")
          .text("session_out", &C::session_out,
                "session folder written at exit (--session-out), atomically: what a later run "
                "needs to localise in this map and extend it; empty = none")
          .text("groundtruth_out", &C::groundtruth_out,
                "the source's ground truth (TUM folders, synthetic worlds) written at exit in TUM "
                "format (--groundtruth-out)")
          .text("metrics_out", &C::metrics_out,
                "run metrics as JSON at exit: frames, rate, drops, per-stage and capture-to-pose "
                "latency percentiles (--metrics-out)")
          .number("status_period_s", &C::status_period_s, 0.05, 60.0, "s",
                  "SLAMD_STATUS publication period")
          .number("drain_deadline_s", &C::drain_deadline_s, 0.0, 600.0, "s",
                  "at shutdown, how long the stages may take to finish queued frames before the "
                  "rest is discarded (and counted)")
          .number("heartbeat_period_s", &C::heartbeat_period_s, 0.01, 10.0, "s",
                  "with no frame for this long the capture thread sends a heartbeat so later "
                  "stages can serve commands")
          .number(
              "tracking_queue", &C::tracking_queue, 1, 1000, "frames",
              "frames waiting for tracking; live and real-time sources drop the oldest (1: "
              "tracking always gets the newest frame), datasets played as fast as possible wait")
          .number("filter_queue", &C::filter_queue, 1, 1000, "frames",
                  "tracked frames waiting for the filter (never dropped)")
          .number("publish_queue", &C::publish_queue, 1, 1000, "poses",
                  "poses waiting for publication (never dropped)")
          .number("mapping_queue", &C::mapping_queue, 1, 1000, "frames",
                  "frames waiting for mapping; live runs skip to the newest, datasets played as "
                  "fast as possible wait")
          .number("backend_queue", &C::backend_queue, 1, 100000, "frames",
                  "filtered frames waiting for the back end, never dropped (a lost keyframe would "
                  "break the graph): datasets wait when it is full; on a live source it grows by "
                  "this many at a time rather than hold up the filter")
          .flag("vanishing_point_thread", &C::vanishing_point_thread,
                "detect vanishing points on a thread of their own, in parallel with tracking, "
                "instead of on the filter thread (takes a few ms off the capture-to-pose path)")
          .number("vanishing_point_wait_ms", &C::vanishing_point_wait_ms, 0.0, 1000.0, "ms",
                  "live and real-time sources: how long the filter waits for a frame's detection; "
                  "a later detection is skipped and counted")
          .flag("publish_frames", &C::publish_frames,
                "republish every processed frame (capture.publish.*), so lcm-logger captures the "
                "input and a log can be replayed into slamd")
          .text("map_save_path", &C::map_save_path,
                "where SAVE_MAP writes when the command names no file and no --map-out was given")
          .text("save_dir", &C::save_dir,
                "the only folder (relative to the working directory, created when needed) a "
                "SAVE_MAP command received over LCM may name a file in; empty = commands may not "
                "name files")
          .number("mapping_nice", &C::mapping_nice, 0, 19, "",
                  "niceness of the mapping thread (off the capture-to-pose path) on a live or "
                  "paced source; as fast as possible every stage runs at nice 0")
          .number("backend_nice", &C::backend_nice, 0, 19, "",
                  "niceness of the back-end thread (off the capture-to-pose path) on a live or "
                  "paced source; as fast as possible every stage runs at nice 0")
          .number("memory_limit_mb", &C::memory_limit_mb, 0, 1000000, "MB",
                  "resident memory to stay under, checked with every status message; above 80% "
                  "new keyframes are culled harder and kept without images or map clouds, above "
                  "100% the kept clouds of older keyframes are released too (their map stays, "
                  "but no longer follows corrections) and the map far from the camera is made "
                  "coarser (mapping.coarse_far_*); reported on the status channel; 0 = no limit")
          .number("opencv_threads", &C::opencv_threads, 0, 64, "threads",
                  "OpenCV's own worker threads; 0 runs every OpenCV call on the stage thread that "
                  "makes it (a hidden pool would compete with the stage threads)")
          .text("world_frame", &C::world_frame, "world frame name in published poses")
          .text("camera_frame", &C::camera_frame, "camera frame name in published poses");
  return table;
}

DaemonConfig DaemonConfig::load(Config& config) {
  DaemonConfig c;
  schema().load(config, c);
  if (c.source.empty()) throw ConfigError("daemon.source must not be empty");
  return c;
}

}  // namespace slamd
