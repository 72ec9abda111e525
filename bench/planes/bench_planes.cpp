// bench_planes: cost of plane segmentation per 640x480 frame on one core.
//
//   build/bin/bench_planes --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//
// BM_Segment/<input>/<variant>: PlaneSegmenter::segment on one frame per iteration.
//   input 0 = synthetic room, frame 10 as the pipeline gets it (Kinect v1 sensor model on);
//   input 1 = TUM fr1/xyz, first frame ($SLAMD_DATA_DIR or ../shared/data next to the source
//   tree; skipped with a message when absent).
//   variant 0 = the paper's (full resolution, colour-only growing, Lab threshold 15);
//   variant 1 = the default (4 px grid, colour + depth growing).
//   Counters p50_ms / p95_ms: per-frame percentiles of the thread's CPU time.

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/imgcodecs.hpp>

#include "slamd/capture/tum_dataset.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/latency_histogram.hpp"
#include "slamd/common/time.hpp"
#include "slamd/planes/plane_segmenter.hpp"
#include "slamd/synth/synthetic_source.hpp"

namespace {

std::optional<slamd::RgbdFrame> roomFrame() {
  slamd::Config config;
  slamd::SyntheticSource source("room", slamd::SyntheticConfig::load(config));
  return *source.renderFrame(10);
}

/// The first colour frame of fr1/xyz with the depth image nearest in time.
std::optional<slamd::RgbdFrame> tumFrame() {
  namespace fs = std::filesystem;
  const char* env = std::getenv("SLAMD_DATA_DIR");
  const fs::path root =
      env && *env ? fs::path(env) : fs::path(SLAMD_SOURCE_DIR) / ".." / "shared" / "data";
  const fs::path dir = root / "tum_fr1_xyz";
  if (!fs::is_directory(dir)) return std::nullopt;
  const auto rgb = slamd::readTumFileList((dir / "rgb.txt").string());
  const auto depth = slamd::readTumFileList((dir / "depth.txt").string());
  if (rgb.entries.empty() || depth.entries.empty()) return std::nullopt;
  const auto& color_entry = rgb.entries.front();
  const slamd::TumListEntry* best = &depth.entries.front();
  for (const auto& entry : depth.entries) {
    if (std::abs(entry.timestamp_s - color_entry.timestamp_s) <
        std::abs(best->timestamp_s - color_entry.timestamp_s)) {
      best = &entry;
    }
  }
  slamd::RgbdFrame frame;
  frame.color_bgr = cv::imread((dir / color_entry.path).string(), cv::IMREAD_COLOR);
  const cv::Mat raw = cv::imread((dir / best->path).string(), cv::IMREAD_UNCHANGED);
  if (frame.color_bgr.empty() || raw.empty()) return std::nullopt;
  frame.depth_m = slamd::depthRawToMeters(raw, 5000.0);
  frame.intrinsics.fx = 517.3;
  frame.intrinsics.fy = 516.5;
  frame.intrinsics.cx = 318.6;
  frame.intrinsics.cy = 255.3;
  frame.intrinsics.width = frame.color_bgr.cols;
  frame.intrinsics.height = frame.color_bgr.rows;
  return frame;
}

void BM_Segment(benchmark::State& state) {
  const bool tum = state.range(0) == 1;
  const bool paper = state.range(1) == 0;
  const std::optional<slamd::RgbdFrame> frame = tum ? tumFrame() : roomFrame();
  if (!frame) {
    state.SkipWithError("dataset tum_fr1_xyz not found (set SLAMD_DATA_DIR); skipping");
    return;
  }
  slamd::planes::PlaneSegmenter segmenter(paper ? slamd::planes::PlaneSegmenterParams::paper()
                                                : slamd::planes::PlaneSegmenterParams());
  state.SetLabel(std::string(tum ? "fr1_xyz" : "room") + (paper ? " paper" : " fast"));
  std::vector<double> frame_ms;
  std::size_t planes = 0;
  for (auto _ : state) {
    const double start_ms = slamd::threadCpuMs();
    const auto& result = segmenter.segment(*frame);
    benchmark::DoNotOptimize(result.planes.data());
    frame_ms.push_back(slamd::threadCpuMs() - start_ms);
    planes = result.planes.size();
  }
  state.counters["p50_ms"] = slamd::percentile(frame_ms, 50.0);
  state.counters["p95_ms"] = slamd::percentile(frame_ms, 95.0);
  state.counters["planes"] = static_cast<double>(planes);
}
BENCHMARK(BM_Segment)->ArgsProduct({{0, 1}, {0, 1}})->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
