// slamd-web-feeder: publishes what a busy slamd publishes, for the web viewer's benchmark
// (scripts/bench-web.sh): poses at 30 Hz on a circle, voxel map updates at 10 Hz that grow the
// map by --growth voxels each until it holds --voxels, then replace --churn voxels per update
// (half cleared, half new), a status message at 1 Hz and the keyframes every 2 s.
//
//   slamd-web-feeder --voxels 100000 --seconds 40

#include <chrono>
#include <cmath>
#include <iostream>
#include <thread>

#include "slamd/common/program_options.hpp"
#include "slamd/common/shutdown_signals.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/pose_codec.hpp"

namespace {

using namespace slamd;

constexpr float kResolutionM = 0.05f;

/// The n-th voxel of the map: 10 m x 10 m layers of 200 x 200 finest voxels, one above the other
/// 1 m apart (y down: the first layer is the floor at y = 1.5 m). Every n is a different voxel.
Eigen::Vector3f mapVoxel(std::int64_t n) {
  const std::int64_t side = 200;
  auto centre = [](std::int64_t k) {
    return -5.0f + 0.025f + kResolutionM * static_cast<float>(k);
  };
  const std::int64_t layer = n / (side * side);
  const std::int64_t i = n % (side * side);
  return {centre(i % side), 1.525f - static_cast<float>(layer), centre(i / side)};
}

}  // namespace

int main(int argc, char** argv) {
  ShutdownSignals signals;
  ProgramOptions options("slamd-web-feeder",
                         "Publishes a synthetic slamd stream (poses, a growing voxel map, status) "
                         "for the web viewer's benchmark.");
  options.addOption("voxels", "N", "occupied voxels the map grows to", "100000");
  options.addOption("growth", "N", "voxels added per update while the map grows", "2000");
  options.addOption("churn", "N", "voxels replaced per update once the map is full", "1000");
  options.addOption("seconds", "S", "how long to publish", "40");
  options.addOption("lcm-url", "URL", "LCM URL (overrides lcm.url)");
  if (!options.parse(argc, argv)) return options.exitCode();
  try {
    Config config = options.loadConfig();
    if (options.has("lcm-url")) config.set("lcm.url", options.value("lcm-url"));
    const ChannelConfig channels = ChannelConfig::load(config);
    const std::int64_t target_voxels = std::stoll(options.value("voxels"));
    const std::int64_t growth = std::stoll(options.value("growth"));
    const std::int64_t churn = std::stoll(options.value("churn"));
    const double seconds = std::stod(options.value("seconds"));
    LcmBus bus(channels.lcm_url);

    std::int64_t oldest_voxel = 0;  // the map holds voxels [oldest_voxel, next_voxel)
    std::int64_t next_voxel = 0;
    std::int64_t pose_sequence = 0;
    std::int64_t update_sequence = 0;
    const auto start = std::chrono::steady_clock::now();
    auto next_frame = start;
    for (std::int64_t frame = 0; !signals.requested(); ++frame) {
      const double t_s = std::chrono::duration<double>(next_frame - start).count();
      if (t_s > seconds) break;
      PoseEstimate pose;
      pose.utime = wallClockUtime();
      pose.sequence = pose_sequence++;
      const double angle = 0.3 * t_s;
      pose.T_world_camera.translation() =
          Eigen::Vector3d(2.0 * std::cos(angle), 0.0, 2.0 * std::sin(angle));
      pose.T_world_camera.linear() =
          Eigen::AngleAxisd(-angle, Eigen::Vector3d::UnitY()).toRotationMatrix();
      pose.tracking_state = TrackingState::kOk;
      bus.publishMessage(channels.pose, toPoseMessage(pose));

      if (frame % 3 == 0) {
        MapUpdate update;
        update.utime = pose.utime;
        update.resolution_m = kResolutionM;
        update.frame_id = "world";
        update.sequence = update_sequence++;
        const bool growing = next_voxel - oldest_voxel < target_voxels;
        const std::int64_t added = growing ? growth : churn / 2;
        for (std::int64_t k = 0; k < added; ++k)
          update.voxels.push_back({mapVoxel(next_voxel++), 2.0f});
        if (!growing) {
          for (std::int64_t k = 0; k < churn / 2; ++k) {
            update.voxels.push_back({mapVoxel(oldest_voxel++), -2.0f});
          }
        }
        bus.publishMessage(channels.map_update, toMapUpdateMessage(update));
      }
      if (frame % 30 == 0) {
        slamd::status_t status{};
        status.utime = pose.utime;
        status.num_stages = 1;
        status.stages.resize(1);
        status.stages[0].name = "tracking";
        status.stages[0].rate_hz = 30.0;
        status.tracking_state = static_cast<std::int8_t>(TrackingState::kOk);
        status.map_occupied_voxels = next_voxel - oldest_voxel;
        status.message = "slamd-web-feeder";
        bus.publishMessage(channels.status, status);
      }
      next_frame += std::chrono::microseconds(33333);
      std::this_thread::sleep_until(next_frame);
    }
    std::cerr << "slamd-web-feeder: " << pose_sequence << " poses, " << update_sequence
              << " map updates, " << next_voxel - oldest_voxel << " voxels in the map\n";
  } catch (const std::exception& e) {
    std::cerr << "slamd-web-feeder: " << e.what() << "\n";
    return kExitFailure;
  }
  return kExitOk;
}
