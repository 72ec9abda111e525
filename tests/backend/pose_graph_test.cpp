#include "slamd/backend/pose_graph.hpp"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "pose_graph_rings.hpp"

namespace slamd {
namespace {

SE3 randomPose(std::mt19937& rng, double translation_m, double angle_rad) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vector6d xi;
  for (int k = 0; k < 3; ++k) xi(k) = translation_m * n(rng);
  for (int k = 3; k < 6; ++k) xi(k) = angle_rad * n(rng);
  return expSE3(xi);
}

using test::informationOf;
using test::kLoopSigmaM;
using test::kLoopSigmaRad;
using test::kOdomSigmaM;
using test::kOdomSigmaRad;
using test::makeRing;
using test::noiseSample;
using test::RingGraph;

TEST(PoseGraph, RightJacobianInverseMatchesCentralDifferences) {
  std::mt19937 rng(42);
  for (int trial = 0; trial < 20; ++trial) {
    Vector6d xi = noiseSample(rng, 1.0, trial < 5 ? 1e-6 : 0.8);
    const Matrix6d analytic = rightJacobianInverseSE3(xi);
    Matrix6d numeric;
    const double h = 1e-6;
    for (int k = 0; k < 6; ++k) {
      Vector6d d = Vector6d::Zero();
      d(k) = h;
      numeric.col(k) =
          (logSE3(expSE3(xi) * expSE3(d)) - logSE3(expSE3(xi) * expSE3(-d))) / (2.0 * h);
    }
    EXPECT_LT((analytic - numeric).cwiseAbs().maxCoeff(), 1e-6) << "trial " << trial;
  }
}

TEST(PoseGraph, EdgeJacobiansMatchCentralDifferences) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const SE3 T_world_i = randomPose(rng, 2.0, 1.0);
    const SE3 T_world_j = randomPose(rng, 2.0, 1.0);
    // Measurements near the truth (typical) and far from it (a wrong loop).
    const SE3 Z = (T_world_i.inverse() * T_world_j) *
                  expSE3(noiseSample(rng, trial < 10 ? 0.05 : 1.0, trial < 10 ? 0.05 : 0.9));
    Matrix6d Ji, Jj;
    poseGraphEdgeError(Z, T_world_i, T_world_j, &Ji, &Jj);
    Matrix6d numeric_i, numeric_j;
    const double h = 1e-6;
    for (int k = 0; k < 6; ++k) {
      Vector6d d = Vector6d::Zero();
      d(k) = h;
      numeric_i.col(k) = (poseGraphEdgeError(Z, T_world_i * expSE3(d), T_world_j) -
                          poseGraphEdgeError(Z, T_world_i * expSE3(-d), T_world_j)) /
                         (2.0 * h);
      numeric_j.col(k) = (poseGraphEdgeError(Z, T_world_i, T_world_j * expSE3(d)) -
                          poseGraphEdgeError(Z, T_world_i, T_world_j * expSE3(-d))) /
                         (2.0 * h);
    }
    EXPECT_LT((Ji - numeric_i).cwiseAbs().maxCoeff(), 1e-6) << "trial " << trial;
    EXPECT_LT((Jj - numeric_j).cwiseAbs().maxCoeff(), 1e-6) << "trial " << trial;
  }
}

TEST(PoseGraph, RobustKernelsWeightLargeErrorsDown) {
  double w = 0.0;
  EXPECT_DOUBLE_EQ(robustCost(RobustKernel::kHuber, 1.0, 0.25, &w), 0.25);
  EXPECT_DOUBLE_EQ(w, 1.0);
  EXPECT_DOUBLE_EQ(robustCost(RobustKernel::kHuber, 1.0, 100.0, &w), 19.0);
  EXPECT_DOUBLE_EQ(w, 0.1);
  robustCost(RobustKernel::kCauchy, 1.0, 99.0, &w);
  EXPECT_DOUBLE_EQ(w, 0.01);
  // rho' is the derivative of rho.
  for (RobustKernel kernel : {RobustKernel::kHuber, RobustKernel::kCauchy}) {
    const double s = 7.0;
    const double h = 1e-6;
    robustCost(kernel, 1.5, s, &w);
    const double numeric =
        (robustCost(kernel, 1.5, s + h, nullptr) - robustCost(kernel, 1.5, s - h, nullptr)) /
        (2.0 * h);
    EXPECT_NEAR(w, numeric, 1e-6);
  }
}

double positionErrorM(const RingGraph& ring, int k) {
  return (ring.graph.pose(k).translation() - ring.truth[static_cast<std::size_t>(k)].translation())
      .norm();
}

double rmsPositionErrorM(const RingGraph& ring) {
  double sum = 0.0;
  const int n = static_cast<int>(ring.truth.size());
  for (int k = 0; k < n; ++k) sum += std::pow(positionErrorM(ring, k), 2);
  return std::sqrt(sum / n);
}

// RMS distance (metres) between the poses of two graphs over the same node ids.
double rmsDifferenceM(const PoseGraph& a, const PoseGraph& b) {
  double sum = 0.0;
  for (std::int64_t id : a.nodeIds()) {
    sum += (a.pose(id).translation() - b.pose(id).translation()).squaredNorm();
  }
  return std::sqrt(sum / static_cast<double>(a.numNodes()));
}

TEST(PoseGraph, DriftedRingWithExactMeasurementsConvergesToGroundTruth) {
  std::mt19937 rng(42);
  RingGraph ring = makeRing(150, rng, 0.0);
  const double before_m = rmsPositionErrorM(ring);
  const PoseGraphResult result = ring.graph.optimize(PoseGraphOptions());
  const double after_m = rmsPositionErrorM(ring);
  std::printf(
      "exact ring 150 poses: %s after %d iterations, cost %.3g -> %.3g, %.2f ms; "
      "RMS position error %.3f m -> %.2e m\n",
      optimizationStatusName(result.status), result.iterations, result.initial_cost,
      result.final_cost, result.time_ms, before_m, after_m);
  EXPECT_EQ(result.status, OptimizationStatus::kConverged);
  EXPECT_GT(before_m, 0.3);
  EXPECT_LT(after_m, 1e-6);
  EXPECT_LT(result.final_cost, 1e-9 * result.initial_cost);
  // The first node is the gauge: unchanged.
  EXPECT_TRUE(ring.graph.pose(0).isApprox(ring.truth[0], 1e-12));
}

TEST(PoseGraph, NoisyRingWithLoopEdgesReachesTheNoiseFloor) {
  std::mt19937 rng(42);
  RingGraph ring = makeRing(150, rng);
  const double before_m = rmsPositionErrorM(ring);
  const double end_before_m = positionErrorM(ring, 149);
  const PoseGraphResult result = ring.graph.optimize(PoseGraphOptions());
  const double after_m = rmsPositionErrorM(ring);
  const double end_after_m = positionErrorM(ring, 149);
  std::printf(
      "noisy ring 150 poses: %s after %d iterations, cost %.1f -> %.1f, %.2f ms; "
      "RMS position error %.3f m -> %.3f m, last pose %.3f m -> %.3f m\n",
      optimizationStatusName(result.status), result.iterations, result.initial_cost,
      result.final_cost, result.time_ms, before_m, after_m, end_before_m, end_after_m);
  EXPECT_EQ(result.status, OptimizationStatus::kConverged);
  // At the optimum the cost is about the redundancy: 6 * (edges - free nodes) = 24 (chi-square).
  EXPECT_LT(result.final_cost, 60.0);
  EXPECT_LT(result.final_cost, 0.25 * result.initial_cost);
  EXPECT_LT(end_after_m, end_before_m / 5.0);  // the loop pulls the end back to the start
  EXPECT_LT(after_m, before_m / 1.5);          // the middle keeps the odometry's own noise
  for (std::size_t e = 149; e < ring.graph.numEdges(); ++e) EXPECT_GT(result.edge_weights[e], 0.2);
}

class WrongLoopEdge : public ::testing::TestWithParam<RobustKernel> {};

TEST_P(WrongLoopEdge, IsDownWeightedAndTheSolutionStaysNearTheCleanOne) {
  std::mt19937 rng(42);
  RingGraph clean = makeRing(150, rng);
  PoseGraphOptions options;
  options.robust_kernel = GetParam();
  options.max_iterations = 100;
  clean.graph.optimize(options);
  std::mt19937 rng_same(42);
  RingGraph ring = makeRing(150, rng_same);
  // Nodes 40 and 110 lie across the ring (about 9 m apart); claim they coincide.
  ASSERT_TRUE(ring.graph.addEdge(
      {40, 110, SE3::Identity(), informationOf(kLoopSigmaM, kLoopSigmaRad), EdgeKind::kLoop}));
  const PoseGraphResult result = ring.graph.optimize(options);
  const double shift_m = rmsDifferenceM(ring.graph, clean.graph);
  const double wrong_weight = result.edge_weights.back();
  std::printf(
      "%s: wrong loop weight %.2e, RMS shift from the clean solution %.3f m, RMS error "
      "%.3f m, %d iterations\n",
      robustKernelName(GetParam()), wrong_weight, shift_m, rmsPositionErrorM(ring),
      result.iterations);
  EXPECT_LT(wrong_weight, 0.01);
  // Huber bounds the wrong edge's pull (without a kernel it moves the poses by more than 3 m,
  // see below); Cauchy removes it.
  EXPECT_LT(shift_m, GetParam() == RobustKernel::kCauchy ? 0.01 : 1.0);
  // The true loop edges keep a large weight.
  for (std::size_t e = 149; e + 1 < ring.graph.numEdges(); ++e) {
    EXPECT_GT(result.edge_weights[e], 0.2);
  }
}

INSTANTIATE_TEST_SUITE_P(Kernels, WrongLoopEdge,
                         ::testing::Values(RobustKernel::kHuber, RobustKernel::kCauchy),
                         [](const auto& param_info) {
                           return std::string(robustKernelName(param_info.param));
                         });

TEST(PoseGraph, WithoutARobustKernelAWrongLoopEdgeDistortsTheSolution) {
  PoseGraphOptions options;
  options.robust_kernel = RobustKernel::kNone;
  options.max_iterations = 100;
  std::mt19937 rng(42);
  RingGraph clean = makeRing(150, rng);
  clean.graph.optimize(options);
  std::mt19937 rng_same(42);
  RingGraph ring = makeRing(150, rng_same);
  ring.graph.addEdge(
      {40, 110, SE3::Identity(), informationOf(kLoopSigmaM, kLoopSigmaRad), EdgeKind::kLoop});
  ring.graph.optimize(options);
  const double shift_m = rmsDifferenceM(ring.graph, clean.graph);
  std::printf("none: RMS shift from the clean solution %.3f m\n", shift_m);
  EXPECT_GT(shift_m, 3.0);
}

TEST(PoseGraph, EdgesToMissingNodesAreRejected) {
  PoseGraph graph;
  graph.addNode(0, SE3::Identity());
  EXPECT_FALSE(graph.addEdge({0, 1, SE3::Identity(), Matrix6d::Identity(), EdgeKind::kOdometry}));
  EXPECT_FALSE(graph.addEdge({0, 0, SE3::Identity(), Matrix6d::Identity(), EdgeKind::kOdometry}));
  EXPECT_EQ(graph.optimize(PoseGraphOptions()).status, OptimizationStatus::kInvalidGraph);
}

TEST(BackendConfig, ReadsAndValidatesKeys) {
  Config config = Config::fromYamlString(
      "backend:\n  enabled: true\n  robust_kernel: cauchy\n  max_iterations: 12\n");
  const BackendConfig c = BackendConfig::load(config);
  EXPECT_TRUE(c.enabled);
  EXPECT_EQ(c.robust_kernel, RobustKernel::kCauchy);
  EXPECT_EQ(c.max_iterations, 12);
  Config bad = Config::fromYamlString("backend:\n  robust_kernel_width: -1\n");
  EXPECT_THROW(BackendConfig::load(bad), ConfigError);
  Config bad_kernel = Config::fromYamlString("backend:\n  robust_kernel: tukey\n");
  EXPECT_THROW(BackendConfig::load(bad_kernel), ConfigError);
}

TEST(PoseGraph, RemovingANodeTakesItsEdgesAndKeepsTheOthers) {
  PoseGraph graph;
  for (int id = 0; id < 4; ++id) {
    graph.addNode(id, SE3(Eigen::Translation3d(static_cast<double>(id), 0.0, 0.0)));
  }
  const SE3 step(Eigen::Translation3d(1.0, 0.0, 0.0));
  for (int id = 0; id + 1 < 4; ++id) graph.addEdge({id, id + 1, step, Matrix6d::Identity()});
  graph.addEdge({0, 2, step * step, Matrix6d::Identity(), EdgeKind::kLocal});
  const std::vector<PoseGraphEdge> removed = graph.removeNode(2);
  ASSERT_EQ(removed.size(), 3u);
  EXPECT_FALSE(graph.hasNode(2));
  EXPECT_EQ(graph.numNodes(), 3u);
  EXPECT_EQ(graph.numEdges(), 1u);
  EXPECT_TRUE(graph.removeNode(2).empty()) << "removed twice";
  // The nodes after the removed one keep their poses (the index was rebuilt).
  EXPECT_NEAR(graph.pose(3).translation().x(), 3.0, 1e-12);
  EXPECT_TRUE(graph.isFixed(0));
  EXPECT_FALSE(graph.isFixed(3));
  EXPECT_FALSE(graph.addEdge({1, 2, step, Matrix6d::Identity()}));
  EXPECT_TRUE(graph.addEdge({1, 3, step * step, Matrix6d::Identity()}));
  EXPECT_NE(graph.optimize(PoseGraphOptions()).status, OptimizationStatus::kInvalidGraph);
}

TEST(PoseGraph, ComposedAndInvertedEdgesCarryMeasurementAndCovariance) {
  std::mt19937 rng(5);
  const SE3 T_ab = expSE3((Vector6d() << 0.4, -0.1, 0.2, 0.1, 0.3, -0.2).finished());
  const SE3 T_bc = expSE3((Vector6d() << -0.2, 0.5, 0.1, -0.2, 0.1, 0.4).finished());
  Vector6d sigma_ab;
  sigma_ab << 0.01, 0.02, 0.015, 0.01, 0.005, 0.02;
  Vector6d sigma_bc;
  sigma_bc << 0.02, 0.01, 0.01, 0.003, 0.01, 0.008;
  const PoseGraphEdge ab{0, 1, T_ab, sigma_ab.cwiseAbs2().cwiseInverse().asDiagonal()};
  const PoseGraphEdge bc{1, 2, T_bc, sigma_bc.cwiseAbs2().cwiseInverse().asDiagonal()};
  const PoseGraphEdge ac = composedEdge(ab, bc, EdgeKind::kLoop);
  EXPECT_EQ(ac.from_id, 0);
  EXPECT_EQ(ac.to_id, 2);
  EXPECT_EQ(ac.kind, EdgeKind::kLoop);
  EXPECT_TRUE((ac.T_from_to.matrix() - (T_ab * T_bc).matrix()).isZero(1e-12));
  const PoseGraphEdge back = invertedEdge(invertedEdge(ab));
  EXPECT_TRUE((back.T_from_to.matrix() - T_ab.matrix()).isZero(1e-12));
  EXPECT_TRUE((back.information - ab.information).isZero(1e-6 * ab.information.norm()));
  // Monte Carlo: perturb both measurements on the right with their covariances; the composed
  // measurement's right perturbations must have the composed covariance.
  std::normal_distribution<double> normal(0.0, 1.0);
  Matrix6d sample_covariance = Matrix6d::Zero();
  const SE3 T_ac_inverse = ac.T_from_to.inverse();
  constexpr int kSamples = 20000;
  for (int n = 0; n < kSamples; ++n) {
    Vector6d d_ab;
    Vector6d d_bc;
    for (int k = 0; k < 6; ++k) {
      d_ab(k) = sigma_ab(k) * normal(rng);
      d_bc(k) = sigma_bc(k) * normal(rng);
    }
    const Vector6d e = logSE3(T_ac_inverse * (T_ab * expSE3(d_ab)) * (T_bc * expSE3(d_bc)));
    sample_covariance += e * e.transpose() / kSamples;
  }
  const Matrix6d covariance = ac.information.inverse();
  for (int k = 0; k < 6; ++k) {
    EXPECT_NEAR(std::sqrt(sample_covariance(k, k)), std::sqrt(covariance(k, k)),
                0.05 * std::sqrt(covariance(k, k)))
        << "axis " << k;
  }
}

}  // namespace
}  // namespace slamd
