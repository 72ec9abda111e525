#include "slamd/filter/motion_fusion.hpp"

#include <limits>

#include <gtest/gtest.h>

namespace slamd {
namespace {

SE3 motion(const Eigen::Vector3d& translation_m, const Eigen::Vector3d& rotation_rad) {
  SE3 T = SE3::Identity();
  T.linear() = expSO3(rotation_rad);
  T.translation() = translation_m;
  return T;
}

Matrix6d diagonal(double translation_sigma_m, double rotation_sigma_rad) {
  Vector6d variances;
  variances << Eigen::Vector3d::Constant(translation_sigma_m * translation_sigma_m),
      Eigen::Vector3d::Constant(rotation_sigma_rad * rotation_sigma_rad);
  return variances.asDiagonal();
}

// Planes that measure everything but the translation along the camera's z axis (a corridor
// seen along it): information 1/(1 mm)^2 and 1/(0.05 deg)^2, none along z.
Matrix6d corridorInformation() {
  Vector6d information;
  const double rotation_sigma_rad = 0.05 * M_PI / 180.0;
  information << 1e6, 1e6, 0.0,
      Eigen::Vector3d::Constant(1.0 / (rotation_sigma_rad * rotation_sigma_rad));
  return information.asDiagonal();
}

TEST(FuseMotion, WhatThePlanesMeasureComesFromThemWhatTheyLeaveFreeStaysTracking) {
  // Tracking: 2 cm sigma, 1 deg; it says x = 10 mm, z = 30 mm. The planes say x = 4 mm, z = 0
  // (their guess), and measure x tightly but not z.
  const SE3 tracked = motion({0.010, 0.0, 0.030}, {0.0, 0.002, 0.0});
  const Matrix6d covariance = diagonal(0.02, 1.0 * M_PI / 180.0);
  const SE3 planes = motion({0.004, 0.0, 0.0}, {0.0, 0.0, 0.0});
  const MotionFusionResult fused = fuseMotion(tracked, covariance, planes, corridorInformation());
  ASSERT_TRUE(fused.fused);
  EXPECT_EQ(fused.measured_directions, 5);
  // Across: the planes' value (their sigma 1 mm against 20 mm: within 1% of the difference).
  EXPECT_NEAR(fused.T_prev_curr.translation().x(), 0.004, 0.0001);
  EXPECT_NEAR(fused.T_prev_curr.translation().y(), 0.0, 0.0001);
  // Along: tracking's value and variance, untouched.
  EXPECT_NEAR(fused.T_prev_curr.translation().z(), 0.030, 1e-9);
  EXPECT_NEAR(fused.covariance(2, 2), covariance(2, 2), 1e-12);
  // Across, the variance is the planes' (just under).
  EXPECT_LT(fused.covariance(0, 0), 1e-6);
  EXPECT_GT(fused.covariance(0, 0), 0.99e-6);
  // The rotation comes from the planes too.
  EXPECT_LT(rotationAngleRad(fused.T_prev_curr.linear()), 1e-5);
}

TEST(FuseMotion, TheInformationIsRotatedIntoThePreviousFrame) {
  // The planes' information is about the current camera frame's axes (right perturbation): a
  // camera turned 90 degrees about y has its z axis along the previous frame's x. With nothing
  // measured along the current z, the previous frame's x keeps tracking's value.
  const Eigen::Vector3d turn(0.0, M_PI / 2.0, 0.0);
  const SE3 tracked = motion({0.020, 0.0, 0.010}, turn);
  const SE3 planes = motion({0.0, 0.0, 0.0}, turn);
  const MotionFusionResult fused =
      fuseMotion(tracked, diagonal(0.02, 0.02), planes, corridorInformation());
  ASSERT_TRUE(fused.fused);
  EXPECT_NEAR(fused.T_prev_curr.translation().x(), 0.020, 1e-9);  // free: tracking's
  EXPECT_NEAR(fused.T_prev_curr.translation().z(), 0.0, 0.0001);  // measured: the planes'
}

TEST(FuseMotion, AnIncrementFarOutsideBothUncertaintiesIsGated) {
  const SE3 tracked = motion({0.010, 0.0, 0.0}, {0.0, 0.0, 0.0});
  const Matrix6d covariance = diagonal(0.005, 0.01);
  // 10 cm across where tracking allows 5 mm and the planes 1 mm.
  const SE3 planes = motion({0.110, 0.0, 0.0}, {0.0, 0.0, 0.0});
  const MotionFusionResult fused = fuseMotion(tracked, covariance, planes, corridorInformation());
  EXPECT_FALSE(fused.fused);
  EXPECT_EQ(fused.measured_directions, 5);
  EXPECT_GT(fused.nis, fused.gate_chi2);
  EXPECT_TRUE(fused.T_prev_curr.isApprox(tracked));
  EXPECT_TRUE(fused.covariance.isApprox(covariance));
  // Along the free direction any disagreement is allowed: it is not measured.
  const SE3 far_along = motion({0.010, 0.0, 1.0}, {0.0, 0.0, 0.0});
  EXPECT_TRUE(fuseMotion(tracked, covariance, far_along, corridorInformation()).fused);
}

TEST(FuseMotion, NothingMeasuredOrNonFiniteInputsLeaveTrackingAsItWas) {
  const SE3 tracked = motion({0.010, 0.0, 0.0}, {0.0, 0.01, 0.0});
  const Matrix6d covariance = diagonal(0.01, 0.01);
  const MotionFusionResult none =
      fuseMotion(tracked, covariance, SE3::Identity(), Matrix6d::Zero());
  EXPECT_FALSE(none.fused);
  EXPECT_EQ(none.measured_directions, 0);
  Matrix6d bad = corridorInformation();
  bad(0, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(fuseMotion(tracked, covariance, SE3::Identity(), bad).fused);
  EXPECT_TRUE(fuseMotion(tracked, covariance, SE3::Identity(), bad).T_prev_curr.isApprox(tracked));
}

TEST(TranslationInformation, IsTheInverseOfTheTranslationBlockOfTheCovariance) {
  // A coupled information matrix: marginalising the rotation gives the information of the
  // translation alone, (Sigma_tt)^-1.
  Matrix6d A = Matrix6d::Random();
  const Matrix6d information = A * A.transpose() + Matrix6d::Identity();
  const Matrix6d covariance = information.inverse();
  const Matrix6d marginal = translationInformation(information);
  const Eigen::Matrix3d expected = covariance.topLeftCorner<3, 3>().inverse();
  const Eigen::Matrix3d translation_block = marginal.topLeftCorner<3, 3>();
  EXPECT_TRUE(translation_block.isApprox(expected, 1e-9));
  EXPECT_TRUE(marginal.rightCols<3>().isZero());
  EXPECT_TRUE(marginal.bottomRows<3>().isZero());
  // Fused, it moves the translation and leaves a rotation without correlation alone.
  const SE3 tracked = motion({0.010, 0.0, 0.0}, {0.0, 0.01, 0.0});
  const SE3 measured = motion({0.0, 0.0, 0.0}, {0.0, 0.0, 0.0});
  const MotionFusionResult fused = fuseMotion(tracked, diagonal(0.01, 0.01), measured,
                                              translationInformation(corridorInformation()));
  ASSERT_TRUE(fused.fused);
  EXPECT_EQ(fused.measured_directions, 2);
  EXPECT_NEAR(fused.T_prev_curr.translation().x(), 0.0, 0.0002);
  EXPECT_NEAR(logSO3(fused.T_prev_curr.linear()).y(), 0.01, 1e-9);
}

TEST(ChiSquareQuantile, KnownValues) {
  EXPECT_NEAR(chiSquareQuantile(2, 0.95), 5.991, 1e-3);
  EXPECT_NEAR(chiSquareQuantile(5, 0.999), 20.515, 1e-3);
  EXPECT_NEAR(chiSquareQuantile(6, 0.99), 16.812, 1e-3);
}

}  // namespace
}  // namespace slamd
