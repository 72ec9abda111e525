#include "slamd/eval/trajectory_error.hpp"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "slamd/eval/trajectory_plot.hpp"
#include "test_data.hpp"

namespace slamd::eval {
namespace {

// A smooth 20 s trajectory at 30 Hz with motion on every axis.
Trajectory wavyTrajectory(double start_s = 1000.0) {
  Trajectory trajectory;
  for (int i = 0; i < 600; ++i) {
    const double t = i / 30.0;
    StampedPose pose;
    pose.timestamp_s = start_s + t;
    Vector6d xi;
    xi << std::sin(0.3 * t), 0.5 * std::cos(0.2 * t), 0.1 * t, 0.2 * std::sin(0.5 * t), 0.1 * t,
        0.05 * std::cos(t);
    pose.T_world_camera = expSE3(xi);
    trajectory.push_back(pose);
  }
  return trajectory;
}

TEST(Ate, MatchesTheBenchmarkToolOnTheReferenceTrajectories) {
  const auto dir = test::findDataset("eval_reference");
  if (!dir) GTEST_SKIP() << test::missingDataMessage("eval_reference");
  const Trajectory gt = readTumTrajectory((*dir / "fr2_desk_groundtruth.txt").string());
  const Trajectory est = readTumTrajectory((*dir / "fr2_desk_ORB.txt").string());
  const AteResult ate = computeAte(gt, est);
  // evaluate_ate.py --verbose on the same files (../shared/data/README.md).
  EXPECT_EQ(ate.pairs.size(), 2223u);
  EXPECT_NEAR(ate.translation_m.rmse, 0.008144, 1e-6);
  EXPECT_NEAR(ate.translation_m.mean, 0.007514, 1e-6);
  EXPECT_NEAR(ate.translation_m.median, 0.007432, 1e-6);
  EXPECT_NEAR(ate.translation_m.std, 0.003140, 1e-6);
  EXPECT_NEAR(ate.translation_m.min, 0.000332, 1e-6);
  EXPECT_NEAR(ate.translation_m.max, 0.024329, 1e-6);
}

TEST(Ate, RigidOffsetIsRemovedExactlyBySe3Alignment) {
  const Trajectory gt = wavyTrajectory();
  Trajectory est = gt;
  const SE3 T_est_gt = expSE3((Vector6d() << 3.0, -1.0, 0.5, 0.3, -0.2, 1.1).finished());
  for (auto& pose : est) pose.T_world_camera = T_est_gt * pose.T_world_camera;
  const AteResult aligned = computeAte(gt, est);
  EXPECT_EQ(aligned.pairs.size(), gt.size());
  EXPECT_LT(aligned.translation_m.rmse, 1e-9);
  AteOptions no_alignment;
  no_alignment.alignment = AlignmentModel::kNone;
  EXPECT_GT(computeAte(gt, est, no_alignment).translation_m.rmse, 1.0);
}

TEST(Ate, KnownPositionErrorGivesExactStatistics) {
  const Trajectory gt = wavyTrajectory();
  Trajectory est = gt;
  // Alternate +-2 cm along z: zero mean, so SE(3) alignment cannot absorb it.
  for (std::size_t i = 0; i < est.size(); ++i) {
    est[i].T_world_camera.translation().z() += (i % 2 == 0 ? 0.02 : -0.02);
  }
  const AteResult ate = computeAte(gt, est);
  EXPECT_NEAR(ate.translation_m.rmse, 0.02, 2e-4);
  EXPECT_NEAR(ate.translation_m.median, 0.02, 2e-4);
  EXPECT_NEAR(ate.translation_m.std, 0.0, 2e-4);
}

TEST(Ate, Sim3AlignmentRecoversScale) {
  const Trajectory gt = wavyTrajectory();
  Trajectory est = gt;
  const SE3 T_est_gt = expSE3((Vector6d() << 1.0, 2.0, 3.0, 0.1, 0.2, 0.3).finished());
  for (auto& pose : est) {
    pose.T_world_camera = T_est_gt * pose.T_world_camera;
    pose.T_world_camera.translation() *= 0.5;
  }
  AteOptions sim3;
  sim3.alignment = AlignmentModel::kSim3;
  const AteResult result = computeAte(gt, est, sim3);
  EXPECT_LT(result.translation_m.rmse, 1e-9);
  EXPECT_NEAR(result.alignment.scale, 2.0, 1e-9);
  EXPECT_GT(computeAte(gt, est).translation_m.rmse, 0.1);  // SE(3) cannot fix scale
}

TEST(Ate, TimeOffsetIsAppliedBeforeAssociation) {
  const Trajectory gt = wavyTrajectory();
  Trajectory est = gt;
  for (auto& pose : est) pose.timestamp_s += 0.5;  // a clock 0.5 s ahead
  AteOptions options;
  options.association.offset_s = -0.5;
  const AteResult result = computeAte(gt, est, options);
  EXPECT_EQ(result.pairs.size(), gt.size());
  EXPECT_LT(result.translation_m.rmse, 1e-9);
}

TEST(Association, IsGreedyOnDifferenceWithinTheMaximum) {
  const std::vector<double> first = {1.000, 1.030, 1.060, 2.000};
  const std::vector<double> second = {1.001, 1.029, 1.045, 2.050};
  AssociationOptions options;
  options.max_difference_s = 0.02;
  const auto pairs = associateTimestamps(first, second, options);
  // 1.000-1.001 and 1.030-1.029 first (smallest differences); 1.060 then takes 1.045 (0.015);
  // 2.000-2.050 differs by more than the maximum.
  ASSERT_EQ(pairs.size(), 3u);
  EXPECT_EQ(pairs[0].first, 0u);
  EXPECT_EQ(pairs[0].second, 0u);
  EXPECT_EQ(pairs[1].first, 1u);
  EXPECT_EQ(pairs[1].second, 1u);
  EXPECT_EQ(pairs[2].first, 2u);
  EXPECT_EQ(pairs[2].second, 2u);
}

TEST(Association, EachTimestampIsUsedOnce) {
  const std::vector<double> first = {1.000, 1.002};
  const std::vector<double> second = {1.001};
  const auto pairs = associateTimestamps(first, second, AssociationOptions{});
  ASSERT_EQ(pairs.size(), 1u);
}

TEST(Rpe, ConstantDriftGivesExactRelativeErrors) {
  const Trajectory gt = wavyTrajectory();
  Trajectory est;
  // The estimate drifts 1 cm per second along its own x axis and 1 degree per second in yaw.
  const double drift_mps = 0.01;
  const double drift_radps = M_PI / 180.0;
  for (const auto& pose : gt) {
    const double t = pose.timestamp_s - gt.front().timestamp_s;
    StampedPose drifted = pose;
    Vector6d xi;
    xi << drift_mps * t, 0, 0, 0, 0, drift_radps * t;
    drifted.T_world_camera = expSE3(xi) * pose.T_world_camera;
    est.push_back(drifted);
  }
  RpeOptions options;
  options.delta = 1.0;
  options.delta_unit = DeltaUnit::kSeconds;
  const RpeResult rpe = computeRpe(gt, est, options);
  ASSERT_GT(rpe.pairs.size(), 500u);
  // A world-frame drift of 1 degree per second rotates every relative pose by exactly 1 degree.
  EXPECT_NEAR(rpe.rotation_deg.mean, 1.0, 1e-6);
  EXPECT_NEAR(rpe.rotation_deg.std, 0.0, 1e-6);
  EXPECT_GT(rpe.translation_m.mean, 0.0);
  // Without drift, every error is zero.
  const RpeResult perfect = computeRpe(gt, gt, options);
  EXPECT_LT(perfect.translation_m.max, 1e-9);
  // The angle comes from acos of the trace, as evaluate_rpe.py computes it: about 1e-6 degrees of
  // rounding noise near zero.
  EXPECT_LT(perfect.rotation_deg.max, 1e-5);
}

TEST(Rpe, FrameDeltaCountsPoses) {
  const Trajectory gt = wavyTrajectory();
  RpeOptions options;
  options.delta = 30;
  options.delta_unit = DeltaUnit::kFrames;
  const RpeResult rpe = computeRpe(gt, gt, options);
  // evaluate_rpe.py keeps (i, j) only when j is not the last pose: i + 30 < 599, so 569 pairs.
  EXPECT_EQ(rpe.pairs.size(), gt.size() - 30 - 1);
  EXPECT_EQ(rpe.pairs.front().timestamp_est_1_s - rpe.pairs.front().timestamp_est_0_s,
            gt[30].timestamp_s - gt[0].timestamp_s);
}

TEST(Statistics, MatchTheTextbookDefinitions) {
  const ErrorStatistics s = computeStatistics({3.0, 4.0});
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(12.5));
  EXPECT_DOUBLE_EQ(s.mean, 3.5);
  EXPECT_DOUBLE_EQ(s.median, 3.5);
  EXPECT_DOUBLE_EQ(s.std, 0.5);  // population std, as numpy.std
  EXPECT_DOUBLE_EQ(s.min, 3.0);
  EXPECT_DOUBLE_EQ(s.max, 4.0);
}

}  // namespace
}  // namespace slamd::eval
