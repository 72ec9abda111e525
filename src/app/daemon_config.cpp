#include "slamd/app/daemon_config.hpp"

namespace slamd {

DaemonConfig DaemonConfig::load(Config& config) {
  DaemonConfig c;
  c.source = config.getString("daemon.source", c.source);
  c.trajectory_out = config.getString("daemon.trajectory_out", c.trajectory_out);
  c.map_out = config.getString("daemon.map_out", c.map_out);
  c.groundtruth_out = config.getString("daemon.groundtruth_out", c.groundtruth_out);
  c.metrics_out = config.getString("daemon.metrics_out", c.metrics_out);
  c.status_period_s = config.getDouble("daemon.status_period_s", c.status_period_s, 0.05, 60.0);
  c.drain_deadline_s = config.getDouble("daemon.drain_deadline_s", c.drain_deadline_s, 0.0, 600.0);
  c.heartbeat_period_s =
      config.getDouble("daemon.heartbeat_period_s", c.heartbeat_period_s, 0.01, 10.0);
  c.tracking_queue = config.getInt("daemon.tracking_queue", c.tracking_queue, 1, 1000);
  c.filter_queue = config.getInt("daemon.filter_queue", c.filter_queue, 1, 1000);
  c.publish_queue = config.getInt("daemon.publish_queue", c.publish_queue, 1, 1000);
  c.mapping_queue = config.getInt("daemon.mapping_queue", c.mapping_queue, 1, 1000);
  c.backend_queue = config.getInt("daemon.backend_queue", c.backend_queue, 1, 100000);
  c.vanishing_point_thread = config.getBool("daemon.vanishing_point_thread",
                                           c.vanishing_point_thread);
  c.vanishing_point_wait_ms =
      config.getDouble("daemon.vanishing_point_wait_ms", c.vanishing_point_wait_ms, 0.0, 1000.0);
  c.publish_frames = config.getBool("daemon.publish_frames", c.publish_frames);
  c.mapping_enabled = config.getBool("mapping.enabled", c.mapping_enabled);
  c.map_keyframes_only = config.getBool("mapping.keyframes_only", c.map_keyframes_only);
  c.map_save_path = config.getString("daemon.map_save_path", c.map_save_path);
  c.save_dir = config.getString("daemon.save_dir", c.save_dir);
  c.mapping_nice = config.getInt("daemon.mapping_nice", c.mapping_nice, 0, 19);
  c.backend_nice = config.getInt("daemon.backend_nice", c.backend_nice, 0, 19);
  c.opencv_threads = config.getInt("daemon.opencv_threads", c.opencv_threads, 0, 64);
  c.world_frame = config.getString("daemon.world_frame", c.world_frame);
  c.camera_frame = config.getString("daemon.camera_frame", c.camera_frame);
  if (c.source.empty()) throw ConfigError("daemon.source must not be empty");
  return c;
}

}  // namespace slamd
