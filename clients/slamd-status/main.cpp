// slamd-status: a live terminal table of a running slamd's pipeline: stage rates, latencies,
// queue depths, drops and errors, end-to-end latency, tracking state and map size.
//
//   slamd-status            # refreshes in place until Ctrl-C
//   slamd-status --once     # prints the next status message and exits (scripts, tests)

#include <unistd.h>

#include <cstdio>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>

#include "slamd/common/pose_estimate.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/shutdown_signals.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/status_codec.hpp"
#include "slamd/status_t.hpp"

int main(int argc, char** argv) {
  using namespace slamd;
  ShutdownSignals signals;
  ProgramOptions options("slamd-status", "Shows the live status of a running slamd daemon.");
  options.addFlag("once", "print the next status message and exit");
  options.addOption("timeout", "SECONDS", "with --once: give up after this long", "5");
  options.addOption("lcm-url", "URL", "LCM URL (overrides lcm.url)");
  if (!options.parse(argc, argv)) return options.exitCode();
  try {
    Config config = options.loadConfig();
    if (options.has("lcm-url")) config.set("lcm.url", options.value("lcm-url"));
    const ChannelConfig channels = ChannelConfig::load(config);
    const bool once = options.flag("once");
    const double timeout_s = std::stod(options.value("timeout"));
    const bool terminal = isatty(STDOUT_FILENO) && !once;

    std::mutex mutex;
    std::optional<slamd::status_t> latest;
    bool fresh = false;
    LcmBus bus(channels.lcm_url);
    bus.subscribe<slamd::status_t>(channels.status, [&](const slamd::status_t& status, Utime) {
      std::lock_guard<std::mutex> lock(mutex);
      latest = status;
      fresh = true;
      if (once) signals.request();
    });
    bus.startHandling();
    const std::int64_t start_ns = steadyNowNs();
    while (true) {
      const bool stop = signals.waitFor(std::chrono::milliseconds(200));
      std::lock_guard<std::mutex> lock(mutex);
      if (fresh && latest) {
        if (terminal) std::cout << "\033[H\033[2J";  // home + clear: redraw in place
        std::cout << renderStatusTable(*latest, bus.malformedCount(channels.status)) << std::flush;
        fresh = false;
      }
      if (stop) break;
      if (once && (steadyNowNs() - start_ns) * 1e-9 > timeout_s) {
        std::cerr << "slamd-status: no status on " << channels.status << " within " << timeout_s
                  << " s (is slamd running on this LCM URL?)\n";
        return kExitFailure;
      }
    }
    bus.stopHandling();
  } catch (const std::exception& e) {
    std::cerr << "slamd-status: " << e.what() << "\n";
    return kExitFailure;
  }
  return kExitOk;
}
