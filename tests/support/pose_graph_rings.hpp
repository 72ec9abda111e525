#pragma once
// Pose graphs for tests of the back end: a ring of poses (radius 5 m, gentle height and tilt
// changes) whose odometry drifts, with loop edges that tie the end back to the start, and the
// noise and information helpers they are made with.
//
//   std::mt19937 rng(42);
//   test::RingGraph ring = test::makeRing(150, rng);  // ring.truth: exact poses
//   ring.graph.optimize(PoseGraphOptions());

#include <cmath>
#include <random>
#include <vector>

#include "slamd/backend/pose_graph.hpp"

namespace slamd::test {

/// A 6-vector [translation; rotation] of independent Gaussian noise (metres, radians).
inline Vector6d noiseSample(std::mt19937& rng, double sigma_m, double sigma_rad) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vector6d xi;
  for (int k = 0; k < 3; ++k) xi(k) = sigma_m * n(rng);
  for (int k = 3; k < 6; ++k) xi(k) = sigma_rad * n(rng);
  return xi;
}

/// Diagonal information for these standard deviations (metres, radians).
inline Matrix6d informationOf(double sigma_m, double sigma_rad) {
  Vector6d d;
  d << Eigen::Vector3d::Constant(1.0 / (sigma_m * sigma_m)),
      Eigen::Vector3d::Constant(1.0 / (sigma_rad * sigma_rad));
  return d.asDiagonal();
}

struct RingGraph {
  std::vector<SE3, Eigen::aligned_allocator<SE3>> truth;
  PoseGraph graph;
};

constexpr double kOdomSigmaM = 0.02;
constexpr double kOdomSigmaRad = 0.01;
constexpr double kLoopSigmaM = 0.02;
constexpr double kLoopSigmaRad = 0.01;

/// n poses; node ids 0 .. n-1, node 0 fixed. Initial values always drift (the odometry chain
/// with noise); the measurements carry noise_scale times that noise (0 = exact measurements).
/// Loop edges: the last 4 poses see the first 4.
inline RingGraph makeRing(int n, std::mt19937& rng, double noise_scale = 1.0) {
  RingGraph ring;
  for (int k = 0; k < n; ++k) {
    const double a = 2.0 * M_PI * k / n;
    SE3 T = SE3::Identity();
    T.translation() = Eigen::Vector3d(5.0 * std::cos(a), 5.0 * std::sin(a), 0.3 * std::sin(3 * a));
    T.linear() = expSO3(Eigen::Vector3d(0.05 * std::sin(2 * a), 0.05 * std::cos(a), a + M_PI / 2));
    ring.truth.push_back(T);
  }
  SE3 T_world_est = ring.truth[0];
  ring.graph.addNode(0, T_world_est);
  for (int k = 1; k < n; ++k) {
    const Vector6d noise = noiseSample(rng, kOdomSigmaM, kOdomSigmaRad);
    const SE3 Z_true = ring.truth[k - 1].inverse() * ring.truth[k];
    T_world_est = T_world_est * Z_true * expSE3(noise);
    ring.graph.addNode(k, T_world_est);
    ring.graph.addEdge({k - 1, k, Z_true * expSE3(noise_scale * noise),
                        informationOf(kOdomSigmaM, kOdomSigmaRad), EdgeKind::kOdometry});
  }
  for (int k = 0; k < 4; ++k) {
    const int i = k;
    const int j = n - 1 - k;
    const SE3 Z = ring.truth[i].inverse() * ring.truth[j] *
                  expSE3(noise_scale * noiseSample(rng, kLoopSigmaM, kLoopSigmaRad));
    ring.graph.addEdge({i, j, Z, informationOf(kLoopSigmaM, kLoopSigmaRad), EdgeKind::kLoop});
  }
  return ring;
}

}  // namespace slamd::test
