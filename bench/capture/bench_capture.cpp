// bench_capture: decode + pre-processing time per 640x480 frame for each source slamd reads.
//
//   build/bin/bench_capture [--benchmark_filter=Tum] [--benchmark_repetitions=5]
//
// Every benchmark times each frame and reports p50_ms / p95_ms over all frames it handled (the
// issue's figures), besides Google Benchmark's mean time per iteration. Inputs: the TUM fr1/xyz
// sequence from ../shared/data (or $SLAMD_DATA_DIR); the LCM benchmarks decode messages encoded
// from its first frames (no network), so they measure slamd's own work per received message; the
// OpenNI2 benchmark reads the DummyDevice (320x240) and the synthetic one renders a corridor.

#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <vector>

#include <benchmark/benchmark.h>

#include "slamd/capture/depth_preprocessor.hpp"
#include "slamd/capture/tum_source.hpp"
#include "slamd/common/latency_histogram.hpp"
#include "slamd/common/time.hpp"
#include "slamd/comms/frame_codec.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/sources/create_frame_source.hpp"

namespace slamd {
namespace {

std::filesystem::path tumFolder() {
  const char* env = std::getenv("SLAMD_DATA_DIR");
  const std::filesystem::path root =
      env && *env ? std::filesystem::path(env)
                  : std::filesystem::path(SLAMD_SOURCE_DIR) / ".." / "shared" / "data";
  return root / "tum_fr1_xyz";
}

Config tumConfig() {
  return Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/tum_fr1.yaml");
}

// Per-frame wall and CPU times of one benchmark.
struct FrameTimes {
  std::vector<double> wall_ms;
  std::vector<double> cpu_ms;
  std::int64_t wall_start = 0;
  double cpu_start = 0.0;
  void start() {
    wall_start = steadyNowNs();
    cpu_start = threadCpuMs();
  }
  void stop() {
    wall_ms.push_back(static_cast<double>(steadyNowNs() - wall_start) * 1e-6);
    cpu_ms.push_back(threadCpuMs() - cpu_start);
  }
};

void reportPercentiles(benchmark::State& state, const FrameTimes& times) {
  if (times.wall_ms.empty()) return;
  state.counters["p50_ms"] = percentile(times.wall_ms, 50.0);
  state.counters["p95_ms"] = percentile(times.wall_ms, 95.0);
  state.counters["cpu_p50_ms"] = percentile(times.cpu_ms, 50.0);
  state.counters["cpu_p95_ms"] = percentile(times.cpu_ms, 95.0);
  state.counters["frames"] = static_cast<double>(times.wall_ms.size());
}

enum class Steps { kNone, kDefault, kWithBilateral };

DepthPreprocessorConfig stepsConfig(Steps steps) {
  DepthPreprocessorConfig config;  // defaults: range gate + flying pixels
  config.range_gate = steps != Steps::kNone;
  config.flying_pixels = steps != Steps::kNone;
  config.bilateral = steps == Steps::kWithBilateral;
  return config;
}

// TUM folder: read + decode the JPEG colour and PNG depth, then pre-process.
void tumFrame(benchmark::State& state, Steps steps) {
  if (!std::filesystem::is_directory(tumFolder())) {
    state.SkipWithError("tum_fr1_xyz not found (set SLAMD_DATA_DIR)");
    return;
  }
  Config config = tumConfig();
  TumSource source(tumFolder().string(), TumSourceConfig::load(config));
  source.open();
  DepthPreprocessor pre(stepsConfig(steps));
  FrameTimes ms;
  for (auto _ : state) {
    ms.start();
    FrameRead read = source.next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) {
      state.PauseTiming();
      source.open();
      state.ResumeTiming();
      continue;
    }
    cv::Mat depth = read.frame->depth_m;  // the source's own new image: safe to clean in place
    pre.process(depth);
    benchmark::DoNotOptimize(depth.data);
    ms.stop();
  }
  reportPercentiles(state, ms);
}

void BM_TumJpegPngDecode(benchmark::State& state) { tumFrame(state, Steps::kNone); }
void BM_TumJpegPngDecodeAndPreprocess(benchmark::State& state) { tumFrame(state, Steps::kDefault); }
void BM_TumJpegPngDecodeAndPreprocessWithBilateral(benchmark::State& state) {
  tumFrame(state, Steps::kWithBilateral);
}

// Frames of fr1/xyz, for the message and pre-processing benchmarks.
std::vector<RgbdFramePtr> loadFrames(int count) {
  std::vector<RgbdFramePtr> frames;
  if (!std::filesystem::is_directory(tumFolder())) return frames;
  Config config = tumConfig();
  TumSource source(tumFolder().string(), TumSourceConfig::load(config));
  source.open();
  while (static_cast<int>(frames.size()) < count) {
    FrameRead read = source.next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status == FrameRead::Status::kFrame) frames.push_back(read.frame);
  }
  return frames;
}

// LCM slamd.rgbd_frame_t (JPEG colour, PNG or zlib depth): checked decode of the message bytes,
// image decoding, then default pre-processing.
void lcmRgbdFrame(benchmark::State& state, DepthEncoding depth_encoding) {
  const auto frames = loadFrames(20);
  if (frames.empty()) {
    state.SkipWithError("tum_fr1_xyz not found (set SLAMD_DATA_DIR)");
    return;
  }
  FrameEncodeOptions options;
  options.depth = depth_encoding;
  options.depth_scale = 5000.0;
  std::vector<std::vector<std::uint8_t>> messages;
  for (const auto& f : frames) messages.push_back(encodeMessage(encodeRgbdFrame(*f, options)));
  DepthPreprocessor pre(stepsConfig(Steps::kDefault));
  FrameTimes ms;
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& bytes = messages[i++ % messages.size()];
    ms.start();
    auto message = decodeMessage<slamd::rgbd_frame_t>(bytes.data(), bytes.size());
    RgbdFrame frame = decodeRgbdFrame(*message);
    pre.process(frame.depth_m);
    benchmark::DoNotOptimize(frame.depth_m.data);
    ms.stop();
  }
  state.counters["message_kB"] = static_cast<double>(messages[0].size()) / 1000.0;
  reportPercentiles(state, ms);
}

void BM_LcmRgbdJpegPngDecodeAndPreprocess(benchmark::State& state) {
  lcmRgbdFrame(state, DepthEncoding::kPngU16);
}
void BM_LcmRgbdJpegZlibDecodeAndPreprocess(benchmark::State& state) {
  lcmRgbdFrame(state, DepthEncoding::kZlibU16);
}

// LCM kinect.frame_msg_t (JPEG colour, zlib millimetre depth).
void BM_LcmKinectJpegZlibDecodeAndPreprocess(benchmark::State& state) {
  const auto frames = loadFrames(20);
  if (frames.empty()) {
    state.SkipWithError("tum_fr1_xyz not found (set SLAMD_DATA_DIR)");
    return;
  }
  std::vector<std::vector<std::uint8_t>> messages;
  for (const auto& f : frames) messages.push_back(encodeMessage(encodeKinectFrame(*f, true, true)));
  const CameraIntrinsics intrinsics = frames[0]->intrinsics;
  DepthPreprocessor pre(stepsConfig(Steps::kDefault));
  FrameTimes ms;
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& bytes = messages[i++ % messages.size()];
    ms.start();
    auto message = decodeMessage<kinect::frame_msg_t>(bytes.data(), bytes.size());
    RgbdFrame frame = decodeKinectFrame(*message, intrinsics);
    pre.process(frame.depth_m);
    benchmark::DoNotOptimize(frame.depth_m.data);
    ms.stop();
  }
  state.counters["message_kB"] = static_cast<double>(messages[0].size()) / 1000.0;
  reportPercentiles(state, ms);
}

// Any source built by createRawFrameSource: CPU time of next() per frame (for a live device the
// wall time is the device's frame period, so only cpu_* matter), plus default pre-processing.
void sourceFrames(benchmark::State& state, const std::string& spec, Config config) {
  std::unique_ptr<FrameSource> source;
  try {
    source = createRawFrameSource(spec, config);
    source->open();
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  DepthPreprocessor pre(stepsConfig(Steps::kDefault));
  FrameTimes ms;
  for (auto _ : state) {
    ms.start();
    FrameRead read;
    do {
      read = source->next(std::chrono::milliseconds(1000));
    } while (read.status == FrameRead::Status::kTimeout);
    if (read.status != FrameRead::Status::kFrame) {
      state.SkipWithError(("source ended or skipped: " + read.message).c_str());
      break;
    }
    cv::Mat depth = read.frame->depth_m.clone();
    pre.process(depth);
    benchmark::DoNotOptimize(depth.data);
    ms.stop();
  }
  source->close();
  reportPercentiles(state, ms);
}

void BM_OpenNi2DummyFrameAndPreprocess(benchmark::State& state) {
  sourceFrames(state, "openni2:Dummy", Config());  // 320x240: the DummyDevice's only mode
}

void BM_SyntheticCorridorFrameAndPreprocess(benchmark::State& state) {
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/synthetic.yaml");
  sourceFrames(state, "synthetic:corridor", config);
}

// Each pre-processing step alone on fr1/xyz depth (640x480).
void preprocessStep(benchmark::State& state, int step) {
  const auto frames = loadFrames(10);
  if (frames.empty()) {
    state.SkipWithError("tum_fr1_xyz not found (set SLAMD_DATA_DIR)");
    return;
  }
  DepthPreprocessor pre(stepsConfig(Steps::kWithBilateral));
  FrameTimes ms;
  std::size_t i = 0;
  cv::Mat depth;
  for (auto _ : state) {
    state.PauseTiming();
    frames[i++ % frames.size()]->depth_m.copyTo(depth);
    state.ResumeTiming();
    ms.start();
    if (step == 0) pre.rangeGate(depth);
    if (step == 1) pre.removeFlyingPixels(depth);
    if (step == 2) pre.bilateral(depth);
    benchmark::DoNotOptimize(depth.data);
    ms.stop();
  }
  reportPercentiles(state, ms);
}

void BM_PreprocessRangeGate(benchmark::State& state) { preprocessStep(state, 0); }
void BM_PreprocessFlyingPixels(benchmark::State& state) { preprocessStep(state, 1); }
void BM_PreprocessBilateral(benchmark::State& state) { preprocessStep(state, 2); }

BENCHMARK(BM_TumJpegPngDecode)->Unit(benchmark::kMillisecond)->Iterations(300);
BENCHMARK(BM_TumJpegPngDecodeAndPreprocess)->Unit(benchmark::kMillisecond)->Iterations(300);
BENCHMARK(BM_TumJpegPngDecodeAndPreprocessWithBilateral)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(200);
BENCHMARK(BM_LcmRgbdJpegPngDecodeAndPreprocess)->Unit(benchmark::kMillisecond)->Iterations(200);
BENCHMARK(BM_LcmRgbdJpegZlibDecodeAndPreprocess)->Unit(benchmark::kMillisecond)->Iterations(200);
BENCHMARK(BM_LcmKinectJpegZlibDecodeAndPreprocess)->Unit(benchmark::kMillisecond)->Iterations(200);
BENCHMARK(BM_OpenNi2DummyFrameAndPreprocess)->Unit(benchmark::kMillisecond)->Iterations(60);
BENCHMARK(BM_SyntheticCorridorFrameAndPreprocess)->Unit(benchmark::kMillisecond)->Iterations(60);
BENCHMARK(BM_PreprocessRangeGate)->Unit(benchmark::kMillisecond)->Iterations(200);
BENCHMARK(BM_PreprocessFlyingPixels)->Unit(benchmark::kMillisecond)->Iterations(200);
BENCHMARK(BM_PreprocessBilateral)->Unit(benchmark::kMillisecond)->Iterations(100);

}  // namespace
}  // namespace slamd

BENCHMARK_MAIN();
