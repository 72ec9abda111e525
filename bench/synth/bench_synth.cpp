// bench_synth: cost of slamd's synthetic worlds on one core.
//
//   build/bin/bench_synth --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//
// BM_RenderExact/<scene>: one 640x480 exact render (colour + depth) per iteration, cycling over
//   the scene's default trajectory; counters p50_ms / p95_ms are per-frame percentiles of the
//   thread's CPU time (one core's work, unaffected by other processes sharing the core; compare
//   the CPU column, not wall time, on a loaded machine).
// BM_SourceFrame/<scene>: a full frame as the pipeline gets it (render + Kinect v1 model + grey).
// BM_SensorDepth: the depth sensor model alone on a corridor render.
// BM_BuildScene/<scene>: procedural scene construction (textures included).

#include <ctime>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "slamd/common/config.hpp"
#include "slamd/common/latency_histogram.hpp"
#include "slamd/common/time.hpp"
#include "slamd/synth/synthetic_source.hpp"

namespace {

const char* const kScenes[] = {"corridor", "corridor_loop", "room"};

std::unique_ptr<slamd::SyntheticSource> makeSource(const std::string& scene) {
  slamd::Config config;
  return std::make_unique<slamd::SyntheticSource>(scene, slamd::SyntheticConfig::load(config));
}

void reportPercentiles(benchmark::State& state, const std::vector<double>& frame_ms) {
  state.counters["p50_ms"] = slamd::percentile(frame_ms, 50.0);
  state.counters["p95_ms"] = slamd::percentile(frame_ms, 95.0);
}

void BM_RenderExact(benchmark::State& state) {
  const auto source = makeSource(kScenes[state.range(0)]);
  state.SetLabel(kScenes[state.range(0)]);
  slamd::synth::RenderOutput out;
  std::vector<double> frame_ms;
  int index = 0;
  for (auto _ : state) {
    const double start_ms = slamd::threadCpuMs();
    source->renderExact(index, out);
    benchmark::DoNotOptimize(out.depth_m.data);
    frame_ms.push_back(slamd::threadCpuMs() - start_ms);
    index = (index + 7) % source->frameCount();
  }
  reportPercentiles(state, frame_ms);
}
BENCHMARK(BM_RenderExact)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);

void BM_SourceFrame(benchmark::State& state) {
  const auto source = makeSource(kScenes[state.range(0)]);
  state.SetLabel(kScenes[state.range(0)]);
  std::vector<double> frame_ms;
  int index = 0;
  for (auto _ : state) {
    const double start_ms = slamd::threadCpuMs();
    auto frame = source->renderFrame(index);
    benchmark::DoNotOptimize(frame.get());
    frame_ms.push_back(slamd::threadCpuMs() - start_ms);
    index = (index + 7) % source->frameCount();
  }
  reportPercentiles(state, frame_ms);
}
BENCHMARK(BM_SourceFrame)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);

void BM_SensorDepth(benchmark::State& state) {
  const auto source = makeSource("corridor");
  slamd::synth::RenderOutput out;
  source->renderExact(10, out);
  const slamd::synth::SensorModel sensor{slamd::synth::SensorParams()};
  std::int64_t frame = 0;
  for (auto _ : state) {
    cv::Mat depth = sensor.measureDepth(out, 42, frame++);
    benchmark::DoNotOptimize(depth.data);
  }
}
BENCHMARK(BM_SensorDepth)->Unit(benchmark::kMillisecond);

void BM_BuildScene(benchmark::State& state) {
  state.SetLabel(kScenes[state.range(0)]);
  for (auto _ : state) {
    auto scene = slamd::synth::makeScene(kScenes[state.range(0)], slamd::synth::SceneParams(), 42);
    benchmark::DoNotOptimize(scene.rects.data());
  }
}
BENCHMARK(BM_BuildScene)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
