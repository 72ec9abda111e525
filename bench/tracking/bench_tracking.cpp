// bench_tracking: per-step costs of visual odometry on synthetic data (seeded, no files needed).
//   build/bin/bench_tracking [--benchmark_filter=Orb]
// Whole-sequence timing and accuracy (fr1/xyz, synthetic worlds) come from slamd-odometry-run.

#include <cmath>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/core.hpp>

#include "slamd/tracking/dense_alignment.hpp"
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

/// Dense alignment's pyramid of one frame (grey, gradients, depth, normals).
void BM_DenseFrame(benchmark::State& state) {
  cv::setNumThreads(1);
  DenseAlignmentOptions options;
  options.finest_level = static_cast<int>(state.range(0));
  const RgbdFrame& frame = sequence()[0];
  for (auto _ : state) {
    const DenseFrame pyramid = makeDenseFrame(frame.gray, frame.depth_m, frame.intrinsics, options);
    benchmark::DoNotOptimize(pyramid.levels.size());
  }
}
BENCHMARK(BM_DenseFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

/// Times dense alignment of frame 3 to frame 0 from the prior given as its motion from frame 3's
/// true pose (T_true_prior) and covariance; reports the result's error, iterations and failure.
void timeDenseAlignment(benchmark::State& state, const DenseAlignmentOptions& options,
                        const SE3& T_true_prior, const Matrix6d& prior_covariance) {
  cv::setNumThreads(1);
  const RgbdFrame& ref_frame = sequence()[0];
  const RgbdFrame& curr_frame = sequence()[3];
  const DenseFrame ref =
      makeDenseFrame(ref_frame.gray, ref_frame.depth_m, ref_frame.intrinsics, options);
  const DenseFrame curr =
      makeDenseFrame(curr_frame.gray, curr_frame.depth_m, curr_frame.intrinsics, options);
  const SE3 truth = pose(0).inverse() * pose(3);
  const SE3 prior = truth * T_true_prior;
  DenseAlignmentResult result;
  for (auto _ : state) {
    result = alignDense(ref, curr, prior, prior_covariance, options);
    benchmark::DoNotOptimize(result.T_ref_curr);
  }
  const SE3 error = truth.inverse() * result.T_ref_curr;
  state.counters["error_mm"] = error.translation().norm() * 1e3;
  state.counters["error_deg"] = rotationAngleRad(error.linear()) * 180.0 / M_PI;
  state.counters["iterations"] = result.iterations;
  state.SetLabel(result.failure);
}

/// From a constant-velocity-like prior (one frame's motion off), finest level as the argument
/// (1 = half resolution, the default).
void BM_DenseAlign(benchmark::State& state) {
  DenseAlignmentOptions options;
  options.finest_level = static_cast<int>(state.range(0));
  Vector6d variance;
  variance << Eigen::Vector3d::Constant(0.02 * 0.02), Eigen::Vector3d::Constant(0.035 * 0.035);
  timeDenseAlignment(state, options, pose(3).inverse() * pose(2), variance.asDiagonal());
}
BENCHMARK(BM_DenseAlign)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

/// From a close prior, as a feature estimate with few inliers gives (0.5 deg and 1 cm off, sigmas
/// 0.3 deg and 1 cm), sampling the argument's number of pixels per level
/// (tracking.few_inliers_dense_max_pixels).
void BM_DenseRefine(benchmark::State& state) {
  DenseAlignmentOptions options;
  options.max_pixels_per_level = static_cast<int>(state.range(0));
  Vector6d offset;
  offset << 0.006, -0.004, 0.006, 0.005, 0.006, -0.003;  // 1 cm, 0.5 deg
  Vector6d variance;
  variance << Eigen::Vector3d::Constant(0.01 * 0.01),
      Eigen::Vector3d::Constant(std::pow(0.3 * M_PI / 180.0, 2));
  timeDenseAlignment(state, options, expSE3(offset), variance.asDiagonal());
}
BENCHMARK(BM_DenseRefine)->Arg(10000)->Arg(20000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace slamd

BENCHMARK_MAIN();
