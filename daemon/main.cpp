// slamd: the real-time RGB-D SLAM daemon. See README.md and `slamd --help`.

#include <malloc.h>

#include <iostream>

#include "slamd/app/config_reference.hpp"
#include "slamd/app/slam_daemon.hpp"
#include "slamd/backend/session.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"

int main(int argc, char** argv) {
  using namespace slamd;
  // Every frame allocates images of 0.3-1.2 MB. glibc would hand such blocks back to the system
  // when freed (mmap, heap trimming), so that each frame page-faulted its buffers in afresh: about
  // a quarter of the capture thread's time. Keeping them in the heap reuses the same pages.
  mallopt(M_MMAP_THRESHOLD, 64 * 1024 * 1024);
  mallopt(M_TRIM_THRESHOLD, 256 * 1024 * 1024);
  ShutdownSignals signals;  // first: blocks SIGINT/SIGTERM before any thread starts
  ProgramOptions options(
      "slamd",
      "Real-time RGB-D SLAM daemon: estimates the camera pose and builds a voxel map from an "
      "RGB-D source, publishing poses, status and maps on LCM. SIGINT/SIGTERM stop it cleanly "
      "(queued frames drained, outputs written); a second signal exits at once.");
  options.addOption("source", "SPEC",
                    "tum:DIR | openni2[:URI] | oni:FILE | lcm:CHANNEL | synthetic:SCENE "
                    "(default: daemon.source)");
  options.addOption("lcm-url", "URL", "LCM URL (default: lcm.url or $LCM_DEFAULT_URL)");
  options.addOption("trajectory-out", "FILE", "write the trajectory (TUM format) at exit");
  options.addOption("map-out", "FILE.bt", "write the map (.bt or .ot) at exit");
  options.addOption("session-in", "DIR",
                    "load the session in DIR at start and localise in its map (backend.mode)");
  options.addOption("session-out", "DIR",
                    "write a session to DIR at exit (map, keyframes, pose graph, vocabulary)");
  options.addOption("groundtruth-out", "FILE",
                    "write the source's ground truth (TUM folders, synthetic worlds) at exit");
  options.addOption("metrics-out", "FILE.json",
                    "write run metrics (rates, drops, latency percentiles) as JSON at exit");
  options.addFlag("describe-config",
                  "print every configuration key (or those of AREA: daemon, mapping, ...) with its "
                  "type, default, range, unit and doc, and exit");
  options.addFlag("json", "with --describe-config: as a JSON array");
  options.addFlag("markdown",
                  "with --describe-config: as Markdown tables (the README's reference)");
  options.setPositional("[AREA]", 0, 1);
  if (!options.parse(argc, argv)) return options.exitCode();
  if (options.flag("describe-config")) {
    try {
      const auto keys =
          describeConfiguration(options.positional().empty() ? "" : options.positional()[0]);
      std::cout << (options.flag("json")       ? configReferenceJson(keys)
                    : options.flag("markdown") ? configReferenceMarkdown(keys)
                                               : configReferenceText(keys));
      return kExitOk;
    } catch (const ConfigError& e) {
      std::cerr << "slamd: " << e.what() << "\n";
      return kExitUsage;
    }
  }
  if (!options.positional().empty() || options.flag("json") || options.flag("markdown")) {
    std::cerr << "slamd: AREA, --json and --markdown go with --describe-config\n"
              << options.usage();
    return kExitUsage;
  }

  DaemonOverrides overrides;
  overrides.source = options.value("source");
  overrides.lcm_url = options.value("lcm-url");
  overrides.trajectory_out = options.value("trajectory-out");
  overrides.map_out = options.value("map-out");
  overrides.groundtruth_out = options.value("groundtruth-out");
  overrides.metrics_out = options.value("metrics-out");
  overrides.session_in = options.value("session-in");
  overrides.session_out = options.value("session-out");
  std::unique_ptr<SlamDaemon> daemon;
  try {
    Config config = options.loadConfig();
    daemon = std::make_unique<SlamDaemon>(config, overrides);
    reportConfig(config, "slamd");
  } catch (const ConfigError& e) {
    std::cerr << "slamd: configuration error: " << e.what() << "\n";
    return kExitConfigError;
  } catch (const SourceError& e) {
    std::cerr << "slamd: source error: " << e.what() << "\n";
    return kExitSourceError;
  } catch (const SessionError& e) {
    std::cerr << "slamd: session refused: " << e.what() << "\n";
    return kExitSessionError;
  } catch (const std::exception& e) {
    std::cerr << "slamd: " << e.what() << "\n";
    return kExitFailure;
  }
  return daemon->run(signals);
}
