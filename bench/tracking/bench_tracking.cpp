// bench_tracking: per-step costs of visual odometry on synthetic data (seeded, no files needed).
//   build/bin/bench_tracking [--benchmark_filter=Orb]
// Whole-sequence timing and accuracy (fr1/xyz, synthetic worlds) come from slamd-odometry-run.

#include <random>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/core.hpp>

#include "slamd/tracking/features.hpp"
#include "slamd/tracking/motion_estimation.hpp"
#include "slamd/tracking/visual_odometry.hpp"
#include "textured_box.hpp"

namespace slamd {
namespace {

SE3 pose(int i) {
  const double t = i / 30.0;
  Vector6d xi;
  xi << 0.3 * std::sin(1.1 * t), 0.1 * std::sin(0.7 * t), 0.25 * t, 0.1 * std::sin(0.9 * t),
      0.15 * std::sin(0.6 * t), 0.05 * t;
  return expSE3(xi);
}

const std::vector<RgbdFrame>& sequence() {
  static const std::vector<RgbdFrame> frames = [] {
    const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 42);
    std::vector<RgbdFrame> out;
    for (int i = 0; i < 30; ++i) out.push_back(box.render(pose(i), test::fr1Camera()));
    return out;
  }();
  return frames;
}

FrontEndType frontEnd(int index) {
  return index == 0 ? FrontEndType::kOrb : index == 1 ? FrontEndType::kFovis : FrontEndType::kSift;
}

void BM_ExtractFeatures(benchmark::State& state) {
  cv::setNumThreads(1);
  TrackingConfig config;
  config.frontend = frontEnd(static_cast<int>(state.range(0)));
  auto extractor = makeFeatureExtractor(config);
  const RgbdFrame& frame = sequence()[0];
  FeatureSet features;
  for (auto _ : state) {
    extractor->extract(frame.gray, features);
    attachGeometry(frame.depth_m, frame.intrinsics, config, features);
    benchmark::DoNotOptimize(features.num_with_depth);
  }
  state.SetLabel(frontEndName(config.frontend));
  state.counters["features"] = static_cast<double>(features.size());
}
BENCHMARK(BM_ExtractFeatures)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

/// One processFrame per iteration over the synthetic sequence, played forwards then backwards so
/// the motion stays continuous.
void BM_ProcessFrame(benchmark::State& state) {
  cv::setNumThreads(1);
  TrackingConfig config;
  config.frontend = frontEnd(static_cast<int>(state.range(0)));
  VisualOdometry vo(config);
  const auto& frames = sequence();
  std::int64_t n = 0;
  int failures = 0;
  for (auto _ : state) {
    const std::int64_t period = 2 * static_cast<std::int64_t>(frames.size()) - 2;
    const std::int64_t k = n % period;
    const std::size_t index =
        static_cast<std::size_t>(k < static_cast<std::int64_t>(frames.size()) ? k : period - k);
    RgbdFrame frame = frames[index];
    frame.utime = 1'000'000 + n * 33'333;
    frame.sequence = n++;
    const OdometryResult r = vo.processFrame(frame);
    if (r.status != OdometryStatus::kOk) ++failures;
  }
  state.SetLabel(frontEndName(config.frontend));
  state.counters["failures"] = failures;
}
BENCHMARK(BM_ProcessFrame)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

std::vector<Correspondence> correspondences(int count, double outlier_fraction) {
  std::mt19937 rng(42);
  const CameraIntrinsics K = test::fr1Camera();
  Vector6d xi;
  xi << 0.05, -0.03, 0.08, 0.04, -0.06, 0.02;
  const SE3 T = expSE3(xi);
  std::uniform_real_distribution<double> u(20.0, 620.0), v(20.0, 460.0), z(0.8, 4.0);
  std::normal_distribution<double> noise(0.0, 0.5);
  std::vector<Correspondence> out;
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector3d p = K.backProject(u(rng), v(rng), z(rng));
    Correspondence c;
    c.point_ref = T * p;
    c.pixel_curr = K.project(p) + Eigen::Vector2d(noise(rng), noise(rng));
    c.depth_curr_m = p.z();
    if (i < count * outlier_fraction) c.pixel_curr = Eigen::Vector2d(u(rng), v(rng));
    out.push_back(c);
  }
  return out;
}

void BM_RansacRigid(benchmark::State& state) {
  const auto matches = correspondences(static_cast<int>(state.range(0)), 0.5);
  std::mt19937 rng(1);
  for (auto _ : state) {
    benchmark::DoNotOptimize(ransacRigid(matches, test::fr1Camera(), 3.0, 200, rng).num_inliers);
  }
}
BENCHMARK(BM_RansacRigid)->Arg(500)->Unit(benchmark::kMicrosecond);

void BM_ConsistentClique(benchmark::State& state) {
  const auto matches = correspondences(static_cast<int>(state.range(0)), 0.5);
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        maximumConsistentClique(matches, test::fr1Camera(), 0.02, 0.0015).size());
  }
}
BENCHMARK(BM_ConsistentClique)->Arg(500)->Unit(benchmark::kMicrosecond);

void BM_RefinePose(benchmark::State& state) {
  const auto matches = correspondences(static_cast<int>(state.range(0)), 0.0);
  const std::vector<std::uint8_t> use(matches.size(), 1);
  Vector6d xi;
  xi << 0.05, -0.03, 0.08, 0.04, -0.06, 0.02;
  const SE3 start = expSE3(xi * 1.02);
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        refinePose(matches, use, test::fr1Camera(), start, RefinementOptions()).iterations);
  }
}
BENCHMARK(BM_RefinePose)->Arg(500)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace slamd

BENCHMARK_MAIN();
