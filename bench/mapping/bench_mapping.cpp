// Mapping benchmarks: per-frame cost of depth -> cloud -> voxel filter -> OcTree insertion at
// 5 cm and 2 cm, for each insertion method, plus the memory the map takes and the sizes of the
// map messages. Frames are 640x480 renders of a 4 x 2.2 x 4.5 m box room seen from its centre
// (tests/mapping/box_room.hpp), cycling through 24 headings so the map stays warm.
//
//   build/bin/bench_mapping                       # everything
//   build/bin/bench_mapping --benchmark_filter=Integrate/50
//
// Counters: insert_ms_p50 (median time of ray casting + OcTree update per frame), frame_ms_p50
// (the whole integrate() call), points_per_s (filtered points inserted per second of
// integrate()), map_MiB (OcTree memory), update_kB_* / full_map_kB (encoded LCM message sizes).

#include <algorithm>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "box_room.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/mapping/mapper.hpp"

namespace slamd {
namespace {

std::vector<std::pair<RgbdFrame, SE3>> renderLap(const test::BoxRoom& room) {
  std::vector<std::pair<RgbdFrame, SE3>> out;
  Utime utime = 1'000'000;
  for (const SE3& T : test::lookAroundPoses(8)) {
    RgbdFrame frame = room.render(T);
    frame.utime = utime += 33'333;
    out.emplace_back(std::move(frame), T);
  }
  return out;
}

/// large = false: the 4 x 2.2 x 4.5 m test room; true: a 10 x 3 x 12 m hall, where most rays
/// run to the 4 m maximum range (the paper-002 scale: about 300,000 valid depths per frame).
const std::vector<std::pair<RgbdFrame, SE3>>& frames(bool large = false) {
  static const auto small_lap = renderLap(test::BoxRoom{});
  static const auto large_lap = [] {
    test::BoxRoom hall;
    hall.min_m = Eigen::Vector3d(-5.02, -1.52, -6.02);
    hall.max_m = Eigen::Vector3d(5.02, 1.52, 6.02);
    return renderLap(hall);
  }();
  return large ? large_lap : small_lap;
}

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + static_cast<long>(values.size() / 2),
                   values.end());
  return values[values.size() / 2];
}

MappingConfig benchConfig(double resolution_m, InsertionMethod method) {
  MappingConfig config;
  config.resolution_m = resolution_m;
  config.voxel_filter_m = resolution_m;
  config.insertion = method;
  config.update_rate_hz = 0.0;
  config.full_map_period_s = 0.0;
  config.snapshot_period_s = 0.0;
  config.keep_keyframe_clouds = false;
  return config;
}

void BM_DepthToCloud(benchmark::State& state) {
  const RgbdFrame& frame = frames().front().first;
  PointCloud cloud;
  DepthCloudStats stats;
  const DepthToCloudOptions options;
  for (auto _ : state) {
    depthToCloud(frame.depth_m, frame.color_bgr, frame.intrinsics, options, cloud, stats);
    benchmark::DoNotOptimize(cloud.points.data());
  }
  state.counters["points"] = static_cast<double>(cloud.size());
}
BENCHMARK(BM_DepthToCloud)->Unit(benchmark::kMillisecond);

void BM_VoxelFilter(benchmark::State& state) {
  const RgbdFrame& frame = frames().front().first;
  PointCloud cloud;
  DepthCloudStats stats;
  depthToCloud(frame.depth_m, frame.color_bgr, frame.intrinsics, {}, cloud, stats);
  const auto mode =
      state.range(1) == 0 ? VoxelFilterMode::kNearestToCentre : VoxelFilterMode::kCentroid;
  VoxelGridFilter filter;
  PointCloud out;
  for (auto _ : state) {
    filter.apply(cloud, static_cast<double>(state.range(0)) / 1000.0, mode, out);
    benchmark::DoNotOptimize(out.points.data());
  }
  state.counters["points_in"] = static_cast<double>(cloud.size());
  state.counters["points_out"] = static_cast<double>(out.size());
  state.SetLabel(toString(mode));
}
BENCHMARK(BM_VoxelFilter)->ArgsProduct({{50, 20}, {0, 1}})->Unit(benchmark::kMillisecond);

/// Args: resolution in mm, insertion method (0 dense, 1 octomap, 2 octomap_discrete), scene
/// (0 room, 1 hall).
void BM_Integrate(benchmark::State& state) {
  const double resolution_m = static_cast<double>(state.range(0)) / 1000.0;
  const auto method = static_cast<InsertionMethod>(state.range(1));
  Mapper mapper(benchConfig(resolution_m, method));
  const auto& all = frames(state.range(2) != 0);
  // One warm-up lap: afterwards most voxels already exist, as in steady-state mapping.
  for (const auto& [frame, T] : all) mapper.integrate(frame, T);
  std::vector<double> insert_ms;
  std::vector<double> raycast_ms;
  std::vector<double> update_ms;
  std::vector<double> frame_ms;
  double points = 0.0;
  double seconds = 0.0;
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& [frame, T] = all[i++ % all.size()];
    const IntegrationResult r = mapper.integrate(frame, T);
    insert_ms.push_back(r.insert_ms);
    raycast_ms.push_back(r.raycast_ms);
    update_ms.push_back(r.update_ms);
    frame_ms.push_back(r.cloud_ms + r.filter_ms + r.insert_ms);
    points += static_cast<double>(r.points_filtered);
    seconds += (r.cloud_ms + r.filter_ms + r.insert_ms) / 1000.0;
  }
  state.counters["insert_ms_p50"] = median(insert_ms);
  state.counters["raycast_ms_p50"] = median(raycast_ms);
  state.counters["update_ms_p50"] = median(update_ms);
  state.counters["frame_ms_p50"] = median(frame_ms);
  state.counters["points_per_frame"] = points / static_cast<double>(insert_ms.size());
  state.counters["points_per_s"] = seconds > 0.0 ? points / seconds : 0.0;
  state.counters["map_MiB"] = static_cast<double>(mapper.memoryBytes()) / (1 << 20);
  state.SetLabel(std::string(toString(method)) + (state.range(2) != 0 ? " hall" : " room"));
}
// Every method at 5 cm in both scenes; at 2 cm OctoMap's own insertion takes seconds per hall
// frame, so only the room compares methods there.
BENCHMARK(BM_Integrate)
    ->ArgsProduct({{50}, {0, 1, 2}, {0, 1}})
    ->Args({20, 0, 0})
    ->Args({20, 1, 0})
    ->Args({20, 0, 1})
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0);

/// Message sizes and the cost of producing a full map at 5 cm and 2 cm (second argument:
/// mapping.update_new_free_voxels). Updates are taken every
/// third frame (10 Hz at 30 Hz input): during the first lap the camera explores (most voxels are
/// new), during the second it revisits (only voxels whose occupancy flips are sent).
void BM_MapMessages(benchmark::State& state) {
  const double resolution_m = static_cast<double>(state.range(0)) / 1000.0;
  MappingConfig config = benchConfig(resolution_m, InsertionMethod::kDenseMask);
  config.update_new_free_voxels = state.range(1) != 0;
  Mapper mapper(config);
  std::vector<double> exploring_bytes;
  std::vector<double> revisiting_bytes;
  std::size_t n = 0;
  for (int lap = 0; lap < 2; ++lap) {
    for (const auto& [frame, T] : frames()) {
      mapper.integrate(frame, T);
      if (++n % 3 == 0) {
        const auto bytes = encodeMessage(toMapUpdateMessage(mapper.takeUpdate())).size();
        (lap == 0 ? exploring_bytes : revisiting_bytes).push_back(static_cast<double>(bytes));
      }
    }
  }
  std::size_t full_bytes = 0;
  for (auto _ : state) {
    full_bytes = encodeMessage(toFullMapMessage(mapper.fullMap())).size();
  }
  state.counters["update_kB_p50_exploring"] = median(exploring_bytes) / 1000.0;
  state.counters["update_kB_p50_revisiting"] = median(revisiting_bytes) / 1000.0;
  state.counters["full_map_kB"] = static_cast<double>(full_bytes) / 1000.0;
  state.counters["map_MiB"] = static_cast<double>(mapper.memoryBytes()) / (1 << 20);
  state.counters["leaves"] = static_cast<double>(mapper.numLeafNodes());
  state.SetLabel(config.update_new_free_voxels ? "with new free voxels" : "occupied + flips");
}
BENCHMARK(BM_MapMessages)->ArgsProduct({{50, 20}, {1, 0}})->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace slamd

BENCHMARK_MAIN();
