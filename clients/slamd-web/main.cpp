// slamd-web: a live web viewer of a running slamd. It subscribes to slamd's LCM streams and
// serves a page (three.js from Debian's libjs-three) showing the camera trail and frustum, the
// keyframes, the voxel map coloured by height, a 2D occupancy view and the status table,
// updated over a WebSocket at 10 Hz.
//
//   slamd-web                         # http://127.0.0.1:8080/ (this machine only)
//   slamd-web --bind 0.0.0.0 --port 8081   # reachable from other machines
//
// It rides through slamd restarts (the page is told to clear) and lost map messages (it asks
// slamd for a full map on SLAMD_COMMAND). The page's protocol: clients/slamd-web/PROTOCOL.md.

#include <chrono>
#include <fstream>
#include <iostream>
#include <sstream>
#include <variant>

#include "slamd/command_t.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/shutdown_signals.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/mapping/mapping_config.hpp"
#include "slamd/pipeline/spsc_queue.hpp"
#include "slamd/web/viewer_model.hpp"
#include "slamd/web/web_server.hpp"

namespace slamd::web {
std::map<std::string, std::string> embeddedPageFiles();  // generated from www/ by the build
}

namespace {

using namespace slamd;
using namespace slamd::web;

constexpr const char* kProgram = "slamd-web";

/// What the LCM thread hands the main thread, decoded and converted.
struct Malformed {};
using Incoming = std::variant<PoseEstimate, KeyframeTrajectory, slamd::status_t,
                              slamd::vanishing_point_t, MapUpdate, FullMap, Malformed>;

std::string contentType(const std::string& path) {
  auto ends_with = [&](const char* suffix) {
    const std::string s(suffix);
    return path.size() >= s.size() && path.compare(path.size() - s.size(), s.size(), s) == 0;
  };
  if (ends_with(".js")) return "text/javascript; charset=utf-8";
  if (ends_with(".css")) return "text/css; charset=utf-8";
  return "text/html; charset=utf-8";
}

/// The page (built in) and three.js (Debian's libjs-three, read now so a missing package is a
/// clear error at start, not a blank page).
std::map<std::string, StaticFile> pageFiles(const std::string& three_dir) {
  std::map<std::string, StaticFile> files;
  for (auto& [url, body] : embeddedPageFiles()) {
    files[url] = StaticFile{contentType(url == "/" ? ".html" : url), body};
  }
  const std::pair<const char*, const char*> debian_files[] = {
      {"/three.min.js", "/build/three.min.js"},
      {"/OrbitControls.js", "/examples/js/controls/OrbitControls.js"},
  };
  for (const auto& [url, relative] : debian_files) {
    const std::string path = three_dir + relative;
    std::ifstream in(path, std::ios::binary);
    std::ostringstream body;
    body << in.rdbuf();
    if (!in || body.str().empty()) {
      throw std::runtime_error("cannot read " + path +
                               " (three.js: install Debian's libjs-three, or give --three-dir)");
    }
    files[url] = StaticFile{contentType(url), body.str()};
  }
  return files;
}

// GCC 12 warns, after inlining, that a moved-from std::variant "may be used uninitialized" in
// these handlers; every alternative is constructed before it is moved.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
void subscribe(LcmBus& bus, const ChannelConfig& channels, SpscQueue<Incoming>& queue,
               std::uint64_t& dropped) {
  auto hand_over = [&queue, &dropped](Incoming item) {
    if (!queue.tryPush(std::move(item))) ++dropped;  // the main thread stalled
  };
  auto on_malformed = [hand_over](const std::string& error) {
    SLAMD_LOG_WARN(kProgram) << error;
    hand_over(Malformed{});
  };
  bus.subscribe<slamd::pose_t>(
      channels.pose, [hand_over](const slamd::pose_t& m, Utime) { hand_over(fromPoseMessage(m)); },
      on_malformed);
  bus.subscribe<slamd::keyframe_trajectory_t>(
      channels.keyframes,
      [hand_over](const slamd::keyframe_trajectory_t& m, Utime) {
        hand_over(fromKeyframeTrajectoryMessage(m));
      },
      on_malformed);
  bus.subscribe<slamd::status_t>(
      channels.status, [hand_over](const slamd::status_t& m, Utime) { hand_over(m); },
      on_malformed);
  bus.subscribe<slamd::vanishing_point_t>(
      channels.vanishing_point,
      [hand_over](const slamd::vanishing_point_t& m, Utime) { hand_over(m); }, on_malformed);
  bus.subscribe<slamd::voxel_map_update_t>(
      channels.map_update,
      [hand_over](const slamd::voxel_map_update_t& m, Utime) {
        std::string error;
        if (auto update = fromMapUpdateMessage(m, &error)) {
          hand_over(std::move(*update));
        } else {
          SLAMD_LOG_WARN(kProgram) << "map update skipped: " << error;
          hand_over(Malformed{});
        }
      },
      on_malformed, 100);
  bus.subscribe<slamd::voxel_map_t>(
      channels.map,
      [hand_over](const slamd::voxel_map_t& m, Utime) {
        std::string error;
        if (auto map = fromFullMapMessage(m, &error)) {
          hand_over(std::move(*map));
        } else {
          SLAMD_LOG_WARN(kProgram) << "full map skipped: " << error;
          hand_over(Malformed{});
        }
      },
      on_malformed, 4);
}
#pragma GCC diagnostic pop

void apply(ViewerModel& model, Incoming& item, std::int64_t now_ns) {
  std::visit(
      [&](auto& message) {
        using T = std::decay_t<decltype(message)>;
        if constexpr (std::is_same_v<T, PoseEstimate>) model.onPose(message, now_ns);
        if constexpr (std::is_same_v<T, KeyframeTrajectory>) model.onKeyframes(message, now_ns);
        if constexpr (std::is_same_v<T, slamd::status_t>) model.onStatus(message, now_ns);
        if constexpr (std::is_same_v<T, slamd::vanishing_point_t>) {
          model.onVanishingPoint(message, now_ns);
        }
        if constexpr (std::is_same_v<T, MapUpdate>) model.onMapUpdate(message, now_ns);
        if constexpr (std::is_same_v<T, FullMap>) {
          std::string error;
          if (!model.onFullMap(message, now_ns, &error)) {
            SLAMD_LOG_WARN(kProgram) << "full map rejected: " << error;
          }
        }
        if constexpr (std::is_same_v<T, Malformed>) model.onMalformed();
      },
      item);
}

}  // namespace

int main(int argc, char** argv) {
  ShutdownSignals signals;
  ProgramOptions options(kProgram,
                         "Serves a live web view of a running slamd: trail, keyframes, voxel map, "
                         "2D occupancy and status.");
  options.addOption("port", "PORT", "HTTP port (0: any free port)", "8080");
  options.addOption("bind", "ADDRESS",
                    "address to listen on (0.0.0.0: every interface; the viewer has no "
                    "authentication)",
                    "127.0.0.1");
  options.addOption("up-axis", "AXIS",
                    "the world's up axis for the page (+x -x +y -y +z -z; default: "
                    "mapping.up_axis)");
  options.addOption("three-dir", "DIR", "three.js installation (Debian's libjs-three)",
                    "/usr/share/javascript/three");
  options.addOption("client-stats-out", "FILE",
                    "append the pages' own measurements (first paint, frame rate, message "
                    "gaps), one JSON object per line");
  options.addOption("lcm-url", "URL", "LCM URL (overrides lcm.url)");
  options.addOption("update-hz", "HZ", "page updates per second", "10");
  if (!options.parse(argc, argv)) return options.exitCode();

  ChannelConfig channels;
  ViewerModel::Options model_options;
  WebServer::Options server_options;
  double update_hz = 10.0;
  try {
    Config config = options.loadConfig();
    if (options.has("lcm-url")) config.set("lcm.url", options.value("lcm-url"));
    if (options.has("up-axis")) config.set("mapping.up_axis", options.value("up-axis"));
    channels = ChannelConfig::load(config);
    model_options.up_axis = toString(MappingConfig::load(config).up_axis);
    reportConfig(config, kProgram, UnknownKeys::kInSectionsItRead);
    server_options.port = std::stoi(options.value("port"));
    server_options.bind_address = options.value("bind");
    update_hz = std::stod(options.value("update-hz"));
    if (server_options.port < 0 || server_options.port > 65535) {
      throw std::runtime_error("--port must be 0..65535");
    }
    if (!(update_hz >= 0.5 && update_hz <= 60.0)) {
      throw std::runtime_error("--update-hz must be 0.5..60");
    }
  } catch (const std::exception& e) {
    std::cerr << kProgram << ": " << e.what() << "\n";
    return kExitConfigError;
  }

  std::ofstream client_stats;
  if (options.has("client-stats-out")) {
    client_stats.open(options.value("client-stats-out"), std::ios::app);
    if (!client_stats) {
      std::cerr << kProgram << ": cannot write " << options.value("client-stats-out") << "\n";
      return kExitOutputError;
    }
  }

  try {
    WebServer server(server_options, pageFiles(options.value("three-dir")));
    LcmBus bus(channels.lcm_url);
    SpscQueue<Incoming> queue(8192);
    std::uint64_t dropped = 0;  // written by the LCM thread only; read at exit
    subscribe(bus, channels, queue, dropped);
    bus.startHandling();
    std::cerr << kProgram << ": serving " << server.url() << " (slamd on "
              << (channels.lcm_url.empty() ? std::string("LCM's default URL") : channels.lcm_url)
              << ")\n";

    ViewerModel model(model_options);
    const auto tick = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / update_hz));
    auto next_tick = std::chrono::steady_clock::now() + tick;
    while (!signals.waitFor(std::chrono::milliseconds(5))) {
      const std::int64_t now_ns = steadyNowNs();
      while (auto item = queue.tryPop()) apply(model, *item, now_ns);
      if (std::chrono::steady_clock::now() < next_tick) continue;
      next_tick += tick;
      if (next_tick < std::chrono::steady_clock::now())
        next_tick = std::chrono::steady_clock::now() + tick;

      for (const ClientText& text : server.takeClientTexts()) {
        if (text.text.find("\"request_full\"") != std::string::npos) {
          server.sendTo(text.client, model.fullState(now_ns));
        } else if (client_stats && text.text.rfind("{\"type\":\"client_stats\"", 0) == 0) {
          client_stats << text.text << "\n" << std::flush;
        }
      }
      model.setClientCount(server.clientCount());
      for (const OutgoingMessage& message : model.takeBroadcast(now_ns)) server.broadcast(message);
      // After the broadcast: a new page's full state is the state just broadcast.
      for (ClientId client : server.takeClientsNeedingFullState()) {
        server.sendTo(client, model.fullState(now_ns));
      }
      if (model.wantsFullMap(now_ns)) {
        slamd::command_t command{};
        command.utime = wallClockUtime();
        command.command = slamd::command_t::PUBLISH_MAP;
        bus.publishMessage(channels.command, command);
        SLAMD_LOG_INFO(kProgram) << "map copy has a gap: asked slamd for a full map";
      }
    }
    bus.stopHandling();
    const ViewerCounters& counters = model.counters();
    std::cerr << kProgram << ": " << counters.poses_received << " poses, " << model.occupiedVoxels()
              << " occupied voxels, " << counters.full_maps << " full maps, "
              << counters.map_requests << " full-map requests, " << counters.restarts
              << " slamd restarts, " << bus.malformedTotal() << " malformed messages, " << dropped
              << " dropped (viewer too slow), " << server.httpRequests() << " HTTP requests, "
              << server.overflows() << " page queue overflows\n";
  } catch (const std::exception& e) {
    std::cerr << kProgram << ": " << e.what() << "\n";
    return kExitFailure;
  }
  return kExitOk;
}
