#pragma once
// DaemonConfig: the daemon's own options (keys `daemon.*`); each stage reads its own section
// (tracking.*, filter.*, mapping.*, capture.*, synthetic.*, channels.*, lcm.*).

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

// Each key's type, default, range, unit and doc: daemon_config.cpp (its one declaration), or
// `slamd --describe-config daemon`. Queues that "wait" block the stage before them; the others
// drop their oldest packet when full (live and real-time sources only).
struct DaemonConfig {
  std::string source = "synthetic:room";
  std::string trajectory_out;
  std::string map_out;
  std::string groundtruth_out;
  std::string metrics_out;
  std::string session_in;
  std::string session_out;
  double status_period_s = 1.0;
  double drain_deadline_s = 5.0;
  double heartbeat_period_s = 0.2;
  int tracking_queue = 1;
  int filter_queue = 8;
  int publish_queue = 16;
  int mapping_queue = 2;
  int backend_queue = 600;
  bool vanishing_point_thread = true;
  double vanishing_point_wait_ms = 5.0;
  bool publish_frames = false;
  std::string map_save_path = "slamd_map.bt";
  std::string save_dir = "maps";
  int mapping_nice = 19;
  int backend_nice = 19;
  int memory_limit_mb = 0;
  int opencv_threads = 0;
  std::string world_frame = "world";
  std::string camera_frame = "camera";

  /// The `daemon.*` keys.
  static const ConfigSchema<DaemonConfig>& schema();
  static DaemonConfig load(Config& config);
};

}  // namespace slamd
