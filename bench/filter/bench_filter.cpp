// Filter benchmarks on 640x480 rendered corridor images: vanishing-point detection alone (Hough
// and LSD), the EKF predict + update alone, and the whole filter step (detection + EKF), the
// number issue 7 targets (median <= 5 ms per frame). Besides Google Benchmark's mean, each
// benchmark reports the per-frame median and 95th percentile (p50_ms, p95_ms).

#include <algorithm>
#include <chrono>
#include <vector>

#include <benchmark/benchmark.h>

#include "corridor_scene.hpp"
#include "slamd/filter/vanishing_point_filter.hpp"

namespace {

using slamd::CameraIntrinsics;
using slamd::SE3;

constexpr int kNumImages = 16;

SE3 corridorPose(int k) {
  SE3 T = SE3::Identity();
  T.linear() = slamd::filter_test::yawPitchRoll(0.2 * std::sin(k * 0.7), 0.05 * std::sin(k * 1.3),
                                                0.03 * std::sin(k * 0.9));
  T.translation() = Eigen::Vector3d(0.3 * std::sin(k * 0.5), 0.05 * std::sin(k * 1.1), 0.05 * k);
  return T;
}

const std::vector<cv::Mat>& corridorImages() {
  static const std::vector<cv::Mat> images = [] {
    std::vector<cv::Mat> out;
    const CameraIntrinsics K;
    for (int k = 0; k < kNumImages; ++k) {
      out.push_back(slamd::filter_test::renderCorridor(K, corridorPose(k), 100u + k));
    }
    return out;
  }();
  return images;
}

/// Per-frame timing: adds p50_ms and p95_ms counters.
class FrameTimes {
 public:
  void add(std::chrono::steady_clock::duration d) {
    ms_.push_back(std::chrono::duration<double, std::milli>(d).count());
  }
  void report(benchmark::State& state) {
    if (ms_.empty()) return;
    std::sort(ms_.begin(), ms_.end());
    state.counters["p50_ms"] = ms_[ms_.size() / 2];
    state.counters["p95_ms"] = ms_[std::min(ms_.size() - 1, ms_.size() * 95 / 100)];
  }

 private:
  std::vector<double> ms_;
};

void BM_DetectVanishingPoint(benchmark::State& state, const char* detector_name,
                             double image_scale) {
  const CameraIntrinsics K;
  slamd::VanishingPointConfig config;
  config.segment_detector = detector_name;
  config.image_scale = image_scale;
  if (image_scale == 1.0) config.blur_kernel_px = 5;
  slamd::VanishingPointDetector detector(K, config);
  const auto& images = corridorImages();
  FrameTimes times;
  int k = 0, found = 0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    const auto vp = detector.detect(images[static_cast<std::size_t>(k++ % kNumImages)]);
    times.add(std::chrono::steady_clock::now() - start);
    found += vp.status == slamd::VanishingPointStatus::kOk;
    benchmark::DoNotOptimize(vp);
  }
  times.report(state);
  state.counters["detected_fraction"] = static_cast<double>(found) / std::max(1, k);
}
BENCHMARK_CAPTURE(BM_DetectVanishingPoint, hough_half, "hough", 0.5)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_DetectVanishingPoint, hough_full, "hough", 1.0)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_DetectVanishingPoint, lsd_half, "lsd", 0.5)->Unit(benchmark::kMillisecond);

void BM_EkfPredictUpdate(benchmark::State& state) {
  const CameraIntrinsics K;
  slamd::FilterConfig config;
  slamd::PoseEkf ekf(config, K);
  ekf.addLandmark(Eigen::Vector2d(K.cx, K.cy), Eigen::Matrix2d::Identity());
  slamd::Matrix6d cov = slamd::Matrix6d::Identity() * 1e-6;
  SE3 step = SE3::Identity();
  step.translation().z() = 0.05;
  for (auto _ : state) {
    ekf.predict(step, cov, 1.0 / 30.0);
    const auto r = ekf.updateVanishingPoint(Eigen::Vector2d(K.cx + 0.3, K.cy - 0.2),
                                            Eigen::Matrix2d::Identity());
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_EkfPredictUpdate)->Unit(benchmark::kMicrosecond);

/// The filter stage per frame: odometry prediction + vanishing-point detection + EKF update.
void BM_FilterStep(benchmark::State& state) {
  const CameraIntrinsics K;
  slamd::VanishingPointFilter filter(slamd::FilterConfig{}, K);
  const auto& images = corridorImages();
  FrameTimes times;
  int k = 0, accepted = 0;
  for (auto _ : state) {
    slamd::FilterInput in;
    const int i = k % kNumImages;
    in.T_prev_curr = corridorPose((i + kNumImages - 1) % kNumImages).inverse() * corridorPose(i);
    in.dt_s = 1.0 / 30.0;
    in.gray = images[static_cast<std::size_t>(i)];
    const auto start = std::chrono::steady_clock::now();
    const auto out = filter.process(in);
    times.add(std::chrono::steady_clock::now() - start);
    accepted += out.update && out.update->accepted;
    ++k;
    benchmark::DoNotOptimize(out);
  }
  times.report(state);
  state.counters["accepted_fraction"] = static_cast<double>(accepted) / std::max(1, k);
}
BENCHMARK(BM_FilterStep)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
