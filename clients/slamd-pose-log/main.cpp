// slamd-pose-log: records the poses a running slamd publishes, as a TUM trajectory or CSV.
//
//   slamd-pose-log --out trajectory.txt                      # until Ctrl-C
//   slamd-pose-log --out poses.csv --format csv --count 300  # stop after 300 poses
//
// Lines are written as poses arrive (flushed every second), so a killed logger keeps what it saw.
// Malformed messages are counted and reported at exit; they never stop the logger.

#include <fstream>
#include <iostream>
#include <mutex>

#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/shutdown_signals.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/pose_codec.hpp"

int main(int argc, char** argv) {
  using namespace slamd;
  ShutdownSignals signals;
  ProgramOptions options("slamd-pose-log", "Records slamd poses (slamd.pose_t) to a file.");
  options.addOption("out", "FILE", "output file (TUM trajectory or CSV)");
  options.addOption("format", "tum|csv", "output format", "tum");
  options.addOption("count", "N", "stop after N poses (0 = until Ctrl-C)", "0");
  options.addOption("timeout", "SECONDS", "stop after this long without a pose (0 = never)", "0");
  options.addOption("lcm-url", "URL", "LCM URL (overrides lcm.url)");
  if (!options.parse(argc, argv)) return options.exitCode();
  ChannelConfig channels;
  long long max_count = 0;
  double timeout_s = 0.0;
  try {
    Config config = options.loadConfig();
    if (options.has("lcm-url")) config.set("lcm.url", options.value("lcm-url"));
    channels = ChannelConfig::load(config);
    reportConfig(config, "slamd-pose-log", UnknownKeys::kInSectionsItRead);
    max_count = std::stoll(options.value("count"));
    timeout_s = std::stod(options.value("timeout"));
  } catch (const std::exception& e) {
    std::cerr << "slamd-pose-log: " << e.what() << "\n";
    return kExitConfigError;
  }
  const std::string format = options.value("format");
  if (format != "tum" && format != "csv") {
    std::cerr << "slamd-pose-log: --format must be tum or csv\n";
    return kExitUsage;
  }
  if (!options.has("out")) {
    std::cerr << "slamd-pose-log: --out FILE is required\n\n" << options.usage();
    return kExitUsage;
  }
  std::ofstream out(options.value("out"));
  if (!out) {
    std::cerr << "slamd-pose-log: cannot write '" << options.value("out") << "'\n";
    return kExitOutputError;
  }
  out << (format == "tum"
              ? "# timestamp tx ty tz qx qy qz qw (slamd-pose-log, channel " + channels.pose + ")\n"
              : std::string(kPoseCsvHeader) + "\n");

  std::mutex mutex;  // the LCM thread writes, the main thread flushes
  long long received = 0;
  std::int64_t last_pose_ns = steadyNowNs();
  try {
    LcmBus bus(channels.lcm_url);
    bus.subscribe<slamd::pose_t>(channels.pose, [&](const slamd::pose_t& message, Utime) {
      const PoseEstimate pose = fromPoseMessage(message);
      std::lock_guard<std::mutex> lock(mutex);
      if (max_count > 0 && received >= max_count) return;
      if (format == "tum") {
        out << formatTumPose(StampedPose{utimeToSeconds(pose.utime), pose.T_world_camera}) << "\n";
      } else {
        out << formatPoseCsv(pose) << "\n";
      }
      ++received;
      last_pose_ns = steadyNowNs();
      if (max_count > 0 && received >= max_count) signals.request();
    });
    bus.startHandling();
    SLAMD_LOG_INFO("slamd-pose-log")
        << "recording " << channels.pose << " to " << options.value("out");
    while (!signals.waitFor(std::chrono::seconds(1))) {
      std::lock_guard<std::mutex> lock(mutex);
      out.flush();
      if (timeout_s > 0 && (steadyNowNs() - last_pose_ns) * 1e-9 > timeout_s) break;
    }
    bus.stopHandling();
    std::lock_guard<std::mutex> lock(mutex);
    out.flush();
    std::cerr << "slamd-pose-log: " << received << " poses written to " << options.value("out")
              << ", " << bus.malformedTotal() << " malformed messages ignored\n";
  } catch (const std::exception& e) {
    std::cerr << "slamd-pose-log: " << e.what() << "\n";
    return kExitFailure;
  }
  return out ? kExitOk : kExitOutputError;
}
