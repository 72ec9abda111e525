// slamd-log-info: summarises an LCM log file (as written by lcm-logger): per channel the number of
// messages, bytes, time span and rate, and, for slamd's own message types, how many decode
// (malformed ones are counted, never fatal).
//
//   slamd-log-info run.lcmlog
//   slamd-log-info run.lcmlog --json      # machine-readable, for scripts and tests

#include <cstdio>
#include <iostream>
#include <map>
#include <string>

#include <lcm/lcm-cpp.hpp>

#include "bot_core/pose_t.hpp"
#include "kinect/frame_msg_t.hpp"
#include "slamd/command_t.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/odometry_t.hpp"
#include "slamd/pose_t.hpp"
#include "slamd/rgbd_frame_t.hpp"
#include "slamd/status_t.hpp"
#include "slamd/vanishing_point_t.hpp"
#include "slamd/voxel_map_t.hpp"
#include "slamd/voxel_map_update_t.hpp"

namespace {

struct ChannelSummary {
  std::int64_t messages = 0;
  std::int64_t bytes = 0;
  std::int64_t first_utime = 0;
  std::int64_t last_utime = 0;
  std::string type = "unknown";
  std::int64_t decoded = 0;
};

template <typename Message>
bool tryType(const void* data, std::size_t size, std::string& type) {
  if (!slamd::decodeMessage<Message>(data, size)) return false;
  type = Message::getTypeName();
  return true;
}

// Identifies the slamd/interop type of a message by decoding it (fingerprints differ per type).
bool identify(const void* data, std::size_t size, std::string& type) {
  return tryType<slamd::pose_t>(data, size, type) || tryType<bot_core::pose_t>(data, size, type) ||
         tryType<slamd::odometry_t>(data, size, type) ||
         tryType<slamd::vanishing_point_t>(data, size, type) ||
         tryType<slamd::voxel_map_t>(data, size, type) ||
         tryType<slamd::voxel_map_update_t>(data, size, type) ||
         tryType<slamd::status_t>(data, size, type) ||
         tryType<slamd::command_t>(data, size, type) ||
         tryType<slamd::rgbd_frame_t>(data, size, type) ||
         tryType<kinect::frame_msg_t>(data, size, type);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace slamd;
  ProgramOptions options("slamd-log-info", "Summarises an LCM log file per channel.");
  options.setPositional("LOGFILE", 1, 1);
  options.addFlag("json", "print JSON instead of a table");
  if (!options.parse(argc, argv)) return options.exitCode();
  const std::string path = options.positional()[0];
  lcm::LogFile log(path, "r");
  if (!log.good()) {
    std::cerr << "slamd-log-info: cannot open LCM log '" << path << "'\n";
    return kExitSourceError;
  }
  std::map<std::string, ChannelSummary> channels;
  std::int64_t events = 0;
  while (const lcm::LogEvent* event = log.readNextEvent()) {
    ++events;
    ChannelSummary& summary = channels[event->channel];
    if (summary.messages == 0) summary.first_utime = event->timestamp;
    summary.last_utime = event->timestamp;
    ++summary.messages;
    summary.bytes += event->datalen;
    std::string type;
    if (identify(event->data, static_cast<std::size_t>(event->datalen), type)) {
      summary.type = type;
      ++summary.decoded;
    }
  }
  if (options.flag("json")) {
    std::cout << "{\"file\": \"" << path << "\", \"events\": " << events << ", \"channels\": {";
    bool first = true;
    for (const auto& [name, s] : channels) {
      std::cout << (first ? "" : ", ") << "\"" << name << "\": {\"messages\": " << s.messages
                << ", \"bytes\": " << s.bytes << ", \"type\": \"" << s.type
                << "\", \"decoded\": " << s.decoded
                << ", \"duration_s\": " << (s.last_utime - s.first_utime) * 1e-6 << "}";
      first = false;
    }
    std::cout << "}}\n";
    return kExitOk;
  }
  std::printf("%s: %lld events\n", path.c_str(), static_cast<long long>(events));
  std::printf("%-20s %9s %12s %9s %8s  %-26s %s\n", "channel", "messages", "bytes", "span s",
              "rate Hz", "type", "decoded");
  for (const auto& [name, s] : channels) {
    const double span_s = static_cast<double>(s.last_utime - s.first_utime) * 1e-6;
    std::printf("%-20s %9lld %12lld %9.2f %8.2f  %-26s %lld\n", name.c_str(),
                static_cast<long long>(s.messages), static_cast<long long>(s.bytes), span_s,
                span_s > 0 ? static_cast<double>(s.messages - 1) / span_s : 0.0, s.type.c_str(),
                static_cast<long long>(s.decoded));
  }
  return kExitOk;
}
