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
//
// BM_PlaneOdometryCorridor/<doors>: plane ICP frame to frame along the plain synthetic corridor
// (see the function). Counters: p50_ms / p95_ms (segmentation + registration per frame), failed
// registrations, frames with one free direction along the corridor / none / other, the
// per-frame error in the measured directions (err_p50/p95_mm, err_p50/p95/max_deg), and after 300
// frames the chained estimate's rotation error (end_rot_deg) and offset across the corridor
// (end_across_m).
//
// BM_PlaneMapRebuild/<keyframes>: PlaneMap's rebuild of the world planes after a correction that
// moves every keyframe, with that many keyframes of the textured 33 m corridor (every 4th frame of
// the zigzag walk, Kinect v1 model, true poses). Counters: rebuild_ms (CPU), keyframe_planes,
// world_planes. How the mapping thread's cost of following a correction grows with the map.

#include <algorithm>
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
#include "slamd/planes/plane_map.hpp"
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

/// BM_PlaneOdometryCorridor/<doors>: plane ICP from frame to frame along slamd's plain corridor
/// (texture density 0.04; doors off / on; Kinect v1 model), frames 0-299 (10 s, about 8 m).
/// Each pair starts from the true motion, so the estimate moves only where the planes measure;
/// the chained estimates show how those directions drift. What issue 23's corridor mode would
/// get from planes, before any fusion.
void BM_PlaneOdometryCorridor(benchmark::State& state) {
  const bool doors = state.range(0) == 1;
  slamd::Config config;
  config.applyOverride("synthetic.texture_density=0.04");
  config.applyOverride(std::string("synthetic.doors=") + (doors ? "true" : "false"));
  const slamd::SyntheticSource source("corridor", slamd::SyntheticConfig::load(config));
  const slamd::Trajectory truth = *source.groundTruth();
  constexpr int kFrames = 300;
  state.SetLabel(doors ? "plain corridor with doors" : "plain corridor without doors");
  const Eigen::Vector3d axis_world =
      (truth[kFrames - 1].T_world_camera.translation() - truth[0].T_world_camera.translation())
          .normalized();
  for (auto _ : state) {
    slamd::planes::PlaneSegmenter segmenters[2];
    const slamd::planes::PlaneSegmentation* previous =
        &segmenters[0].segment(*source.renderFrame(0));
    slamd::SE3 T_world_estimate = truth[0].T_world_camera;
    std::vector<double> frame_ms;
    std::vector<double> error_mm;
    std::vector<double> error_deg;
    int failed = 0;
    int one_free_along = 0;
    int none_free = 0;
    int other_free = 0;
    for (int k = 1; k < kFrames; ++k) {
      const slamd::RgbdFramePtr frame = source.renderFrame(k);
      const slamd::SE3& T_world_k = truth[static_cast<std::size_t>(k)].T_world_camera;
      const slamd::SE3 T_true =
          truth[static_cast<std::size_t>(k - 1)].T_world_camera.inverse() * T_world_k;
      const double start_ms = slamd::threadCpuMs();
      const slamd::planes::PlaneSegmentation& current = segmenters[k % 2].segment(*frame);
      const slamd::planes::IcpResult result =
          slamd::planes::registerPlanes(current, *previous, frame->intrinsics, T_true);
      frame_ms.push_back(slamd::threadCpuMs() - start_ms);
      previous = &current;
      if (!result.ok) {
        ++failed;
        T_world_estimate = T_world_estimate * T_true;
        continue;
      }
      const Eigen::Vector3d axis_camera = T_world_k.linear().transpose() * axis_world;
      if (result.degenerate_directions.empty()) {
        ++none_free;
      } else if (result.degenerate_directions.size() == 1 &&
                 std::abs(result.degenerate_directions[0].head<3>().dot(axis_camera)) > 0.985) {
        ++one_free_along;
      } else {
        ++other_free;
      }
      const slamd::Vector6d error = slamd::planes::observableProjector(result) *
                                    slamd::logSE3(T_true.inverse() * result.T_target_source);
      error_mm.push_back(1e3 * error.head<3>().norm());
      error_deg.push_back(error.tail<3>().norm() * 180.0 / M_PI);
      T_world_estimate = T_world_estimate * result.T_target_source;
    }
    const slamd::SE3 end_error = truth[kFrames - 1].T_world_camera.inverse() * T_world_estimate;
    const Eigen::Vector3d end_offset_world =
        T_world_estimate.translation() - truth[kFrames - 1].T_world_camera.translation();
    state.counters["p50_ms"] = slamd::percentile(frame_ms, 50.0);
    state.counters["p95_ms"] = slamd::percentile(frame_ms, 95.0);
    state.counters["failed"] = failed;
    state.counters["one_free_along"] = one_free_along;
    state.counters["none_free"] = none_free;
    state.counters["other_free"] = other_free;
    state.counters["err_p50_mm"] = slamd::percentile(error_mm, 50.0);
    state.counters["err_p95_mm"] = slamd::percentile(error_mm, 95.0);
    state.counters["err_p50_deg"] = slamd::percentile(error_deg, 50.0);
    state.counters["err_p95_deg"] = slamd::percentile(error_deg, 95.0);
    state.counters["err_max_deg"] =
        error_deg.empty() ? 0.0 : *std::max_element(error_deg.begin(), error_deg.end());
    state.counters["end_rot_deg"] = slamd::rotationAngleRad(end_error.linear()) * 180.0 / M_PI;
    state.counters["end_across_m"] =
        (end_offset_world - end_offset_world.dot(axis_world) * axis_world).norm();
  }
}
BENCHMARK(BM_PlaneOdometryCorridor)->Arg(0)->Arg(1)->Iterations(1)->Unit(benchmark::kMillisecond);

void BM_PlaneMapRebuild(benchmark::State& state) {
  const int keyframes = static_cast<int>(state.range(0));
  constexpr int kFrameStep = 4;
  slamd::Config config;
  config.applyOverride("synthetic.corridor_length_m=33");
  config.applyOverride("synthetic.trajectory=zigzag");
  const slamd::SyntheticSource source("corridor", slamd::SyntheticConfig::load(config));
  const slamd::Trajectory truth = *source.groundTruth();
  if (static_cast<std::size_t>(keyframes * kFrameStep) > truth.size()) {
    state.SkipWithError("the walk has fewer frames than asked for");
    return;
  }
  slamd::planes::PlaneSegmenter segmenter;
  slamd::planes::PlaneMap map;
  std::vector<std::pair<std::int64_t, slamd::SE3>> poses;
  for (int k = 0; k < keyframes; ++k) {
    const int index = k * kFrameStep;
    const slamd::SE3& T_world_camera = truth[static_cast<std::size_t>(index)].T_world_camera;
    map.addKeyframe(k, T_world_camera, segmenter.segment(*source.renderFrame(index)).planes);
    poses.emplace_back(k, T_world_camera);
  }
  std::vector<double> rebuild_ms;
  double shift_m = 0.001;
  for (auto _ : state) {
    // A correction: every keyframe moves by a millimetre, back and forth, so each rebuild is real.
    for (auto& [id, T] : poses) T.translation().x() += shift_m;
    shift_m = -shift_m;
    map.setKeyframePoses(poses);
    const double start_ms = slamd::threadCpuMs();
    benchmark::DoNotOptimize(map.worldPlanes().size());
    rebuild_ms.push_back(slamd::threadCpuMs() - start_ms);
  }
  state.counters["rebuild_ms"] = slamd::percentile(rebuild_ms, 50.0);
  state.counters["keyframe_planes"] = static_cast<double>(map.keyframePlaneCount());
  state.counters["world_planes"] = static_cast<double>(map.worldPlanes().size());
}
BENCHMARK(BM_PlaneMapRebuild)
    ->Arg(25)
    ->Arg(100)
    ->Arg(250)
    ->Iterations(3)
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
