#pragma once
// Simulated odometry for the filter's tests: a true increment T_prev_curr perturbed by noise
// sampled from a diagonal covariance in odometry_t's convention (translation additive in the
// previous camera frame, rotation a right perturbation), and that covariance.

#include <random>

#include "slamd/common/se3.hpp"
#include "slamd/filter/pose_ekf.hpp"

namespace slamd::filter_test {

class NoisyOdometry {
 public:
  NoisyOdometry(double sigma_m, double sigma_rad, unsigned seed)
      : sigma_m_(sigma_m), sigma_rad_(sigma_rad), rng_(seed) {
    covariance_.setZero();
    covariance_.diagonal().head<3>().setConstant(sigma_m * sigma_m);
    covariance_.diagonal().tail<3>().setConstant(sigma_rad * sigma_rad);
  }

  /// The true increment with sampled noise.
  SE3 measure(const SE3& true_prev_curr) {
    Vector6d noise;
    for (int i = 0; i < 6; ++i) noise(i) = normal_(rng_) * (i < 3 ? sigma_m_ : sigma_rad_);
    return PoseEkf::boxplus(true_prev_curr, noise);
  }

  const Matrix6d& covariance() const { return covariance_; }
  std::mt19937& rng() { return rng_; }

 private:
  double sigma_m_, sigma_rad_;
  std::mt19937 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  Matrix6d covariance_;
};

}  // namespace slamd::filter_test
