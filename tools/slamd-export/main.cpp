// slamd-export: turns an LCM log of a slamd run (as lcm-logger writes it) into files that other
// tools read: the trajectory (TUM, or CSV with covariance and tracking state), the map rebuilt
// from the map stream (.bt/.ot for octovis, or PLY), the optimised keyframes (TUM or PLY) and the
// status stream as CSV for plotting.
//
//   slamd-export run.lcmlog --trajectory trajectory.txt --map map.bt
//   slamd-export run.lcmlog --pose-channel POSE --trajectory pose.txt     # bot_core.pose_t
//   slamd-export run.lcmlog --trajectory-csv poses.csv --status-csv status.csv --map-ply map.ply
//
// The log is read once, in order. Malformed messages are counted and skipped, never fatal. Every
// output is written atomically once the whole log has been read; an output that the log holds no
// data for is an error (exit 4) that names the channel and lists the channels the log has.

#include <cstdio>
#include <functional>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "bot_core/pose_t.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/keyframe_trajectory_t.hpp"
#include "slamd/mapping/map_io.hpp"
#include "slamd/pose_t.hpp"
#include "slamd/status_t.hpp"

namespace {

using namespace slamd;

constexpr const char* kProgram = "slamd-export";

const char* const kStatusCsvHeader =
    "utime,stage,rate_hz,latency_p50_ms,latency_p95_ms,latency_p99_ms,queue_depth,queue_capacity,"
    "drops,errors,processed,end_to_end_p50_ms,end_to_end_p95_ms,end_to_end_p99_ms,tracking_state,"
    "map_occupied_voxels,map_total_voxels,num_keyframes,num_loops,num_relocalizations,"
    "memory_rss_mb,memory_limit_mb,memory_pressure";

/// One CSV row per stage of a status message; the message's own fields repeat on every row, so
/// each row stands alone for plotting (one stage's latency over time, say).
void appendStatusRows(const slamd::status_t& status, std::string& csv) {
  char tail[512];
  std::snprintf(tail, sizeof(tail), "%.3f,%.3f,%.3f,%s,%lld,%lld,%d,%d,%d,%.1f,%d,%d",
                status.end_to_end_p50_ms, status.end_to_end_p95_ms, status.end_to_end_p99_ms,
                trackingStateName(static_cast<TrackingState>(status.tracking_state)),
                static_cast<long long>(status.map_occupied_voxels),
                static_cast<long long>(status.map_total_voxels), status.num_keyframes,
                status.num_loops, status.num_relocalizations, status.memory_rss_mb,
                status.memory_limit_mb, static_cast<int>(status.memory_pressure));
  for (const slamd::stage_status_t& stage : status.stages) {
    char head[512];
    std::snprintf(head, sizeof(head), "%lld,%s,%.3f,%.3f,%.3f,%.3f,%d,%d,%lld,%lld,%lld,",
                  static_cast<long long>(status.utime), stage.name.c_str(), stage.rate_hz,
                  stage.latency_p50_ms, stage.latency_p95_ms, stage.latency_p99_ms,
                  stage.queue_depth, stage.queue_capacity, static_cast<long long>(stage.drops),
                  static_cast<long long>(stage.errors), static_cast<long long>(stage.processed));
    csv += head;
    csv += tail;
    csv += '\n';
  }
}

/// Everything the outputs need, gathered in one pass over the log.
struct LogContents {
  std::vector<PoseEstimate> poses;
  std::string pose_type;  ///< the type the pose channel carried
  MapReplica map;
  std::int64_t map_messages = 0;
  std::optional<KeyframeTrajectory> keyframes;  ///< the newest
  std::string status_csv;
  std::int64_t status_messages = 0;
  std::map<std::string, std::int64_t> malformed;  ///< per channel
  std::map<std::string, std::int64_t> messages;   ///< per channel, all channels
  std::int64_t events = 0;
};

struct Channels {
  std::string pose, map, map_update, keyframes, status;
};

template <typename Message>
std::optional<Message> decodeOrCount(const lcm::LogEvent& event, LogContents& contents) {
  auto message = decodeMessage<Message>(event.data, static_cast<std::size_t>(event.datalen));
  if (!message) ++contents.malformed[event.channel];
  return message;
}

void readEvent(const lcm::LogEvent& event, const Channels& channels, LogContents& contents) {
  ++contents.events;
  ++contents.messages[event.channel];
  const auto size = static_cast<std::size_t>(event.datalen);
  if (event.channel == channels.pose) {
    // slamd.pose_t, or bot_core.pose_t (the POSE channel): the fingerprint tells them apart.
    if (auto pose = decodeMessage<slamd::pose_t>(event.data, size)) {
      contents.poses.push_back(fromPoseMessage(*pose));
      contents.pose_type = "slamd.pose_t";
    } else if (auto bot_pose = decodeMessage<bot_core::pose_t>(event.data, size)) {
      contents.poses.push_back(fromBotCorePose(*bot_pose));
      contents.pose_type = "bot_core.pose_t";
    } else {
      ++contents.malformed[event.channel];
    }
  } else if (event.channel == channels.map_update) {
    if (auto message = decodeOrCount<slamd::voxel_map_update_t>(event, contents)) {
      auto update = fromMapUpdateMessage(*message);
      if (update && contents.map.applyUpdate(*update) != MapReplica::UpdateResult::kRejected) {
        ++contents.map_messages;
      } else {
        ++contents.malformed[event.channel];
      }
    }
  } else if (event.channel == channels.map) {
    if (auto message = decodeOrCount<slamd::voxel_map_t>(event, contents)) {
      auto map = fromFullMapMessage(*message);
      if (map && contents.map.applyFullMap(*map)) {
        ++contents.map_messages;
      } else {
        ++contents.malformed[event.channel];
      }
    }
  } else if (event.channel == channels.keyframes) {
    if (auto message = decodeOrCount<slamd::keyframe_trajectory_t>(event, contents)) {
      contents.keyframes = fromKeyframeTrajectoryMessage(*message);
    }
  } else if (event.channel == channels.status) {
    if (auto message = decodeOrCount<slamd::status_t>(event, contents)) {
      appendStatusRows(*message, contents.status_csv);
      ++contents.status_messages;
    }
  }
}

std::string channelList(const LogContents& contents) {
  if (contents.messages.empty()) return "the log holds no messages";
  std::ostringstream text;
  text << "channels in the log:";
  for (const auto& [name, count] : contents.messages) text << " " << name << " (" << count << ")";
  return text.str();
}

/// Writes one output atomically; prints what was written or why not.
class OutputWriter {
 public:
  void write(const std::string& path, const std::string& what,
             const std::function<bool(std::ostream&)>& writer) {
    std::string error;
    if (writeFileAtomically(path, writer, &error)) {
      std::cerr << kProgram << ": " << what << " written to " << path << "\n";
    } else {
      std::cerr << kProgram << ": " << path << ": " << error << "\n";
      exit_code_ = kExitOutputError;
    }
  }
  void writeTum(const std::string& path, const std::string& what, const Trajectory& trajectory,
                const std::string& comment) {
    try {
      writeTumTrajectory(path, trajectory, comment);
      std::cerr << kProgram << ": " << what << " written to " << path << "\n";
    } catch (const std::exception& e) {
      std::cerr << kProgram << ": " << e.what() << "\n";
      exit_code_ = kExitOutputError;
    }
  }
  /// An output the log holds nothing for.
  void missing(const std::string& path, const std::string& why, const LogContents& contents) {
    std::cerr << kProgram << ": not writing " << path << ": " << why << "; "
              << channelList(contents) << "\n";
    if (exit_code_ == kExitOk) exit_code_ = kExitSourceError;
  }
  void fail(int code) { exit_code_ = code; }
  int exitCode() const { return exit_code_; }

 private:
  int exit_code_ = kExitOk;
};

Trajectory keyframeTrajectory(const KeyframeTrajectory& keyframes) {
  Trajectory trajectory;
  for (const KeyframePoseEntry& entry : keyframes.keyframes) {
    trajectory.push_back(StampedPose{utimeToSeconds(entry.utime), entry.T_world_camera});
  }
  return trajectory;
}

void writeOutputs(const ProgramOptions& options, const Channels& channels,
                  const LogContents& contents, OutputWriter& out) {
  const std::string trajectory_path = options.value("trajectory");
  const std::string csv_path = options.value("trajectory-csv");
  if (!trajectory_path.empty() || !csv_path.empty()) {
    if (contents.poses.empty()) {
      for (const std::string& path : {trajectory_path, csv_path}) {
        if (!path.empty()) out.missing(path, "no decodable pose on " + channels.pose, contents);
      }
    }
  }
  if (!trajectory_path.empty() && !contents.poses.empty()) {
    Trajectory trajectory;
    for (const PoseEstimate& pose : contents.poses) {
      trajectory.push_back({utimeToSeconds(pose.utime), pose.T_world_camera});
    }
    out.writeTum(trajectory_path, std::to_string(trajectory.size()) + " poses (TUM)", trajectory,
                 "slamd-export: " + contents.pose_type + " on " + channels.pose);
  }
  if (!csv_path.empty() && !contents.poses.empty()) {
    out.write(csv_path, std::to_string(contents.poses.size()) + " poses (CSV)",
              [&](std::ostream& file) {
                file << kPoseCsvHeader << "\n";
                for (const PoseEstimate& pose : contents.poses) file << formatPoseCsv(pose) << "\n";
                return static_cast<bool>(file);
              });
  }

  const std::string map_path = options.value("map");
  const std::string map_ply_path = options.value("map-ply");
  for (const std::string& path : {map_path, map_ply_path}) {
    if (!path.empty() && contents.map_messages == 0) {
      out.missing(path,
                  "no decodable map message on " + channels.map + " or " + channels.map_update,
                  contents);
    }
  }
  if (contents.map_messages > 0 && (!map_path.empty() || !map_ply_path.empty()) &&
      !contents.map.synchronised()) {
    std::cerr << kProgram << ": warning: the map updates have a gap that no later full map "
              << "healed (messages lost, or the log started late); the map holds what arrived "
              << "before the gap\n";
  }
  if (!map_path.empty() && contents.map_messages > 0) {
    std::string error;
    if (writeOcTreeFile(contents.map.tree(), map_path, &error)) {
      std::cerr << kProgram << ": map of " << contents.map.tree().getNumLeafNodes()
                << " voxels written to " << map_path << "\n";
    } else {
      std::cerr << kProgram << ": " << error << "\n";
      out.fail(kExitOutputError);
    }
  }
  if (!map_ply_path.empty() && contents.map_messages > 0) {
    const PointCloud cloud = occupiedVoxelCentres(contents.map.tree());
    out.write(map_ply_path, std::to_string(cloud.size()) + " occupied voxel centres (PLY)",
              [&](std::ostream& file) { return writePly(file, cloud, PlyFormat::kBinary); });
  }

  const std::string keyframes_path = options.value("keyframes");
  const std::string keyframes_ply_path = options.value("keyframes-ply");
  for (const std::string& path : {keyframes_path, keyframes_ply_path}) {
    if (!path.empty() && !contents.keyframes) {
      out.missing(path, "no decodable keyframe trajectory on " + channels.keyframes, contents);
    }
  }
  if (contents.keyframes) {
    const Trajectory trajectory = keyframeTrajectory(*contents.keyframes);
    if (!keyframes_path.empty()) {
      out.writeTum(keyframes_path, std::to_string(trajectory.size()) + " optimised keyframes (TUM)",
                   trajectory,
                   "slamd-export: the newest keyframe trajectory on " + channels.keyframes);
    }
    if (!keyframes_ply_path.empty()) {
      PointCloud cloud;
      for (const StampedPose& pose : trajectory)
        cloud.points.push_back(pose.T_world_camera.translation().cast<float>());
      out.write(keyframes_ply_path,
                std::to_string(cloud.size()) + " optimised keyframe positions (PLY)",
                [&](std::ostream& file) { return writePly(file, cloud, PlyFormat::kAscii); });
    }
  }

  const std::string status_path = options.value("status-csv");
  if (!status_path.empty()) {
    if (contents.status_messages == 0) {
      out.missing(status_path, "no decodable status on " + channels.status, contents);
    } else {
      out.write(status_path,
                std::to_string(contents.status_messages) + " status messages (CSV, a row a stage)",
                [&](std::ostream& file) {
                  file << kStatusCsvHeader << "\n" << contents.status_csv;
                  return static_cast<bool>(file);
                });
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  ProgramOptions options(kProgram,
                         "Exports an LCM log of a slamd run: trajectory (TUM, CSV), map (.bt, .ot, "
                         "PLY), keyframes (TUM, PLY) and status (CSV).");
  options.setPositional("LOGFILE", 1, 1);
  options.addOption("trajectory", "FILE",
                    "the poses as a TUM trajectory (timestamp tx ty tz qx "
                    "qy qz qw)");
  options.addOption("trajectory-csv", "FILE",
                    "the poses as CSV with covariance diagonal, tracking state and source");
  options.addOption(
      "pose-channel", "CHANNEL",
      "channel of the poses: slamd.pose_t or bot_core.pose_t (default: channels.pose, "
      "SLAMD_POSE)");
  options.addOption("map", "FILE", "the map rebuilt from the map stream, .bt or .ot (octovis)");
  options.addOption("map-ply", "FILE", "the occupied voxel centres of that map as a PLY cloud");
  options.addOption("keyframes", "FILE",
                    "the newest optimised keyframe trajectory (SLAMD_KEYFRAMES) as TUM");
  options.addOption("keyframes-ply", "FILE", "the optimised keyframe positions as a PLY cloud");
  options.addOption("status-csv", "FILE", "the status stream as CSV, one row per stage");
  if (!options.parse(argc, argv)) return options.exitCode();
  const char* outputs[] = {"trajectory", "trajectory-csv", "map",       "map-ply",
                           "keyframes",  "keyframes-ply",  "status-csv"};
  bool any_output = false;
  for (const char* name : outputs) any_output = any_output || options.has(name);
  if (!any_output) {
    std::cerr << kProgram << ": name at least one output (--trajectory, --map, ...)\n\n"
              << options.usage();
    return kExitUsage;
  }
  Channels channels;
  try {
    Config config = options.loadConfig();
    const ChannelConfig names = ChannelConfig::load(config);
    channels = {names.pose, names.map, names.map_update, names.keyframes, names.status};
  } catch (const std::exception& e) {
    std::cerr << kProgram << ": " << e.what() << "\n";
    return kExitConfigError;
  }
  if (options.has("pose-channel")) channels.pose = options.value("pose-channel");

  const std::string path = options.positional()[0];
  lcm::LogFile log(path, "r");
  if (!log.good()) {
    std::cerr << kProgram << ": cannot open LCM log '" << path << "'\n";
    return kExitSourceError;
  }
  LogContents contents;
  while (const lcm::LogEvent* event = log.readNextEvent()) readEvent(*event, channels, contents);
  std::int64_t malformed = 0;
  for (const auto& [channel, count] : contents.malformed) {
    std::cerr << kProgram << ": " << count << " malformed messages on " << channel << " skipped\n";
    malformed += count;
  }
  std::cerr << kProgram << ": " << contents.events << " events read from " << path << " ("
            << malformed << " malformed)\n";
  OutputWriter out;
  writeOutputs(options, channels, contents, out);
  return out.exitCode();
}
