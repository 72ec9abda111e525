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
//
// BM_Register/<input>/<gap>/<variant>: registration of frame i + gap (gap 1 = consecutive
// frames, 10 = non-consecutive) to frame i, from the identity (plane_registration.hpp).
//   input 0 = synthetic room, frames 60 and 60 + gap, exact renders; 1 = the same with the
//   Kinect v1 sensor model; 2 = TUM fr1/xyz, frames 0 and gap.
//   variant 0 = plane ICP (paper 000) on the two frames' segmentations;
//   variant 1 = plane ICP plus segmenting the newer frame (each frame is segmented once in a
//   pipeline); variant 2 = point-to-plane ICP on the whole cloud.
//   Counters: p50_ms / p95_ms CPU time, err_mm / err_deg against the true motion, ok,
//   free_dirs (degenerate directions), points (source points used), iterations.

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
#include "slamd/planes/plane_registration.hpp"
#include "slamd/planes/plane_segmenter.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "test_data.hpp"
#include "tum_frames.hpp"

namespace {

/// Frame `index` of the synthetic room as the pipeline gets it (Kinect v1 sensor model on), or
/// its exact render, with its true pose.
slamd::test::TumFrame roomFrame(int index, bool exact = false) {
  slamd::Config config;
  if (exact) config.applyOverride("synthetic.sensor.exact=true");
  const slamd::SyntheticSource source("room", slamd::SyntheticConfig::load(config));
  slamd::test::TumFrame out;
  out.frame = *source.renderFrame(index);
  out.T_world_camera = (*source.groundTruth())[static_cast<std::size_t>(index)].T_world_camera;
  return out;
}

/// Frame `index` of fr1/xyz; nullopt (with the benchmark skipped) when the dataset is absent.
std::optional<slamd::test::TumFrame> tumFrame(std::size_t index) {
  const auto dir = slamd::test::findDataset("tum_fr1_xyz");
  if (!dir) return std::nullopt;
  return slamd::test::loadTumFrame(*dir, index);
}

void BM_Segment(benchmark::State& state) {
  const bool tum = state.range(0) == 1;
  const bool paper = state.range(1) == 0;
  const std::optional<slamd::test::TumFrame> tum_frame = tum ? tumFrame(0) : roomFrame(10);
  const std::optional<slamd::RgbdFrame> frame =
      tum_frame ? std::optional<slamd::RgbdFrame>(tum_frame->frame) : std::nullopt;
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

/// BM_Register/<input>/<gap>/<variant>: registration of frame i + gap to frame i, from the
/// identity; CPU time per registration and the error against the true motion.
void BM_Register(benchmark::State& state) {
  const int input = static_cast<int>(state.range(0));
  const int gap = static_cast<int>(state.range(1));
  const int variant = static_cast<int>(state.range(2));
  std::optional<slamd::test::TumFrame> source;
  std::optional<slamd::test::TumFrame> target;
  if (input == 2) {
    source = tumFrame(0);
    target = tumFrame(static_cast<std::size_t>(gap));
  } else {
    source = roomFrame(60, input == 0);
    target = roomFrame(60 + gap, input == 0);
  }
  if (!source || !target) {
    state.SkipWithError("dataset tum_fr1_xyz not found (set SLAMD_DATA_DIR); skipping");
    return;
  }
  static const char* const kInputs[] = {"room exact", "room kinect", "fr1_xyz"};
  static const char* const kVariants[] = {"planes", "planes+segmentation", "whole cloud"};
  state.SetLabel(std::string(kInputs[input]) + " gap " + std::to_string(gap) + " " +
                 kVariants[variant]);
  const slamd::SE3 T_target_source_true = target->T_world_camera.inverse() * source->T_world_camera;
  const slamd::CameraIntrinsics& intrinsics = source->frame.intrinsics;
  slamd::planes::PlaneSegmenter source_segmenter;
  slamd::planes::PlaneSegmenter target_segmenter;
  slamd::planes::PlaneSegmentation source_planes = source_segmenter.segment(source->frame);
  slamd::planes::PlaneSegmentation target_planes = target_segmenter.segment(target->frame);
  std::vector<double> frame_ms;
  slamd::planes::IcpResult result;
  for (auto _ : state) {
    const double start_ms = slamd::threadCpuMs();
    if (variant == 2) {
      result = slamd::planes::registerClouds(source->frame.depth_m, target->frame.depth_m,
                                             intrinsics, slamd::SE3::Identity());
    } else {
      // In a pipeline each frame is segmented once and then registered as target and source.
      if (variant == 1) target_planes = target_segmenter.segment(target->frame);
      result = slamd::planes::registerPlanes(source_planes, target_planes, intrinsics,
                                             slamd::SE3::Identity());
    }
    benchmark::DoNotOptimize(result.T_target_source);
    frame_ms.push_back(slamd::threadCpuMs() - start_ms);
  }
  const slamd::SE3 error = T_target_source_true.inverse() * result.T_target_source;
  state.counters["p50_ms"] = slamd::percentile(frame_ms, 50.0);
  state.counters["p95_ms"] = slamd::percentile(frame_ms, 95.0);
  state.counters["ok"] = result.ok ? 1.0 : 0.0;
  state.counters["err_mm"] = 1e3 * error.translation().norm();
  state.counters["err_deg"] = slamd::rotationAngleRad(error.linear()) * 180.0 / M_PI;
  state.counters["free_dirs"] = static_cast<double>(result.degenerate_directions.size());
  state.counters["points"] = static_cast<double>(result.source_points);
  state.counters["iterations"] = static_cast<double>(result.iterations);
}
BENCHMARK(BM_Register)->ArgsProduct({{0, 1, 2}, {1, 10}, {0, 1, 2}})->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
