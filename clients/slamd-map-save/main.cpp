// slamd-map-save: keeps its own copy of slamd's map from the LCM stream (incremental updates on
// SLAMD_MAP_UPDATE, full maps on SLAMD_MAP) and writes it as .bt, .ot and/or a PLY point cloud.
//
//   slamd-map-save --out map.bt                  # until Ctrl-C, then write
//   slamd-map-save --out map.bt --once           # write as soon as one full map has arrived
//   slamd-map-save --out map.bt --ply map.ply --timeout 5   # stop 5 s after the last message
//
// Malformed or inconsistent messages are counted and skipped. A gap in the update sequence (LCM
// over UDP drops a large message when the receive buffer is small) makes the copy wait for a
// full map: it asks slamd for one (PUBLISH_MAP on the command channel, at most once a second)
// rather than waiting for the periodic one.

#include <iostream>
#include <mutex>

#include "slamd/command_t.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/shutdown_signals.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/mapping/map_io.hpp"

int main(int argc, char** argv) {
  using namespace slamd;
  ShutdownSignals signals;
  ProgramOptions options("slamd-map-save",
                         "Builds slamd's map from its LCM stream and writes .bt/.ot/PLY files.");
  options.addOption("out", "FILE", "map file, .bt (maximum likelihood) or .ot (log-odds)");
  options.addOption("ply", "FILE", "also write the occupied voxel centres as a PLY point cloud");
  options.addFlag("once", "write as soon as a full map has been received, then exit");
  options.addOption("timeout", "SECONDS", "stop this long after the last map message (0 = never)",
                    "0");
  options.addOption("lcm-url", "URL", "LCM URL (overrides lcm.url)");
  if (!options.parse(argc, argv)) return options.exitCode();
  if (!options.has("out") && !options.has("ply")) {
    std::cerr << "slamd-map-save: give --out FILE.bt|FILE.ot and/or --ply FILE.ply\n\n"
              << options.usage();
    return kExitUsage;
  }
  ChannelConfig channels;
  double timeout_s = 0.0;
  try {
    Config config = options.loadConfig();
    if (options.has("lcm-url")) config.set("lcm.url", options.value("lcm-url"));
    channels = ChannelConfig::load(config);
    timeout_s = std::stod(options.value("timeout"));
  } catch (const std::exception& e) {
    std::cerr << "slamd-map-save: " << e.what() << "\n";
    return kExitConfigError;
  }

  for (const std::string& path :
       removeStaleTemporaryFiles({options.value("out"), options.value("ply")})) {
    std::cerr << "slamd-map-save: removed " << path
              << ", a temporary file left by an interrupted save\n";
  }

  std::mutex mutex;  // the LCM thread updates the replica; the main thread writes it
  MapReplica replica;
  std::int64_t full_maps = 0;
  std::int64_t inconsistent = 0;
  std::int64_t last_message_ns = steadyNowNs();
  FullMapRequestPacer requests;
  std::int64_t full_map_requests = 0;
  try {
    LcmBus bus(channels.lcm_url);
    bus.subscribe<slamd::voxel_map_update_t>(
        channels.map_update, [&](const slamd::voxel_map_update_t& message, Utime) {
          std::string error;
          std::lock_guard<std::mutex> lock(mutex);
          last_message_ns = steadyNowNs();
          if (auto update = fromMapUpdateMessage(message, &error)) {
            replica.applyUpdate(*update);
          } else {
            ++inconsistent;
            SLAMD_LOG_WARN("slamd-map-save") << "update skipped: " << error;
          }
        });
    bus.subscribe<slamd::voxel_map_t>(channels.map, [&](const slamd::voxel_map_t& message, Utime) {
      std::string error;
      std::lock_guard<std::mutex> lock(mutex);
      last_message_ns = steadyNowNs();
      auto map = fromFullMapMessage(message, &error);
      if (map && replica.applyFullMap(*map, &error)) {
        ++full_maps;
        if (options.flag("once")) signals.request();
      } else {
        ++inconsistent;
        SLAMD_LOG_WARN("slamd-map-save") << "full map skipped: " << error;
      }
    });
    bus.startHandling();
    SLAMD_LOG_INFO("slamd-map-save")
        << "listening on " << channels.map_update << " and " << channels.map;
    while (!signals.waitFor(std::chrono::milliseconds(200))) {
      std::lock_guard<std::mutex> lock(mutex);
      const std::int64_t now_ns = steadyNowNs();
      if (timeout_s > 0 && (now_ns - last_message_ns) * 1e-9 > timeout_s) break;
      if (requests.due(replica, now_ns, 1.0)) {
        slamd::command_t command{};
        command.utime = wallClockUtime();
        command.command = slamd::command_t::PUBLISH_MAP;
        bus.publishMessage(channels.command, command);
        ++full_map_requests;
        SLAMD_LOG_INFO("slamd-map-save") << "map copy has a gap: asked slamd for a full map";
      }
    }
    bus.stopHandling();
    std::lock_guard<std::mutex> lock(mutex);
    std::cerr << "slamd-map-save: " << replica.updatesApplied() << " updates applied, "
              << replica.updatesSkipped() << " skipped, " << full_maps << " full maps ("
              << full_map_requests << " asked for), "
              << inconsistent + static_cast<std::int64_t>(bus.malformedTotal())
              << " malformed or inconsistent messages; " << replica.tree().getNumLeafNodes()
              << " voxels"
              << (replica.synchronised() ? ""
                                         : " (NOT synchronised: a gap in the "
                                           "updates was not yet healed by a "
                                           "full map)")
              << "\n";
    int exit_code = kExitOk;
    std::string error;
    if (options.has("out")) {
      if (writeOcTreeFile(replica.tree(), options.value("out"), &error)) {
        std::cerr << "slamd-map-save: map written to " << options.value("out") << "\n";
      } else {
        std::cerr << "slamd-map-save: " << error << "\n";
        exit_code = kExitOutputError;
      }
    }
    if (options.has("ply")) {
      const PointCloud cloud = occupiedVoxelCentres(replica.tree());
      if (writeFileAtomically(
              options.value("ply"),
              [&](std::ostream& out) { return writePly(out, cloud, PlyFormat::kBinary); },
              &error)) {
        std::cerr << "slamd-map-save: " << cloud.size() << " occupied voxels written to "
                  << options.value("ply") << "\n";
      } else {
        std::cerr << "slamd-map-save: " << error << "\n";
        exit_code = kExitOutputError;
      }
    }
    return exit_code;
  } catch (const std::exception& e) {
    std::cerr << "slamd-map-save: " << e.what() << "\n";
    return kExitFailure;
  }
}
