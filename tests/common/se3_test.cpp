#include "slamd/common/se3.hpp"

#include <random>

#include <gtest/gtest.h>

namespace slamd {
namespace {

Vector6d randomTwist(std::mt19937& rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  Vector6d xi;
  for (int i = 0; i < 6; ++i) xi[i] = u(rng);
  return xi;
}

TEST(Se3, ExpAndLogAreInverse) {
  std::mt19937 rng(42);
  for (int i = 0; i < 200; ++i) {
    const Vector6d xi = randomTwist(rng, 1.5);
    const Vector6d back = logSE3(expSE3(xi));
    EXPECT_LT((back - xi).norm(), 1e-9) << xi.transpose();
  }
}

TEST(Se3, SmallAnglesAreExact) {
  Vector6d xi;
  xi << 0.1, -0.2, 0.3, 1e-9, -2e-9, 3e-9;
  EXPECT_LT((logSE3(expSE3(xi)) - xi).norm(), 1e-15);
  EXPECT_LT((expSO3(xi.tail<3>()) - Eigen::Matrix3d::Identity()).norm(), 1e-8);
}

TEST(Se3, LogSo3NearPi) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, 3).normalized();
  const Eigen::Vector3d phi = axis * (M_PI - 1e-7);
  const Eigen::Vector3d back = logSO3(expSO3(phi));
  EXPECT_NEAR(back.norm(), M_PI - 1e-7, 1e-6);
  EXPECT_LT((expSO3(back) - expSO3(phi)).norm(), 1e-9);
}

TEST(Se3, ExpSo3MatchesEigenAngleAxis) {
  const Eigen::Vector3d phi(0.3, -0.4, 0.5);
  const Eigen::Matrix3d expected =
      Eigen::AngleAxisd(phi.norm(), phi.normalized()).toRotationMatrix();
  EXPECT_LT((expSO3(phi) - expected).norm(), 1e-12);
}

TEST(Se3, AdjointMovesTwistsBetweenFrames) {
  std::mt19937 rng(7);
  for (int i = 0; i < 50; ++i) {
    const SE3 T = expSE3(randomTwist(rng, 1.0));
    const Vector6d xi = randomTwist(rng, 0.3);
    const SE3 lhs = T * expSE3(xi) * T.inverse();
    const SE3 rhs = expSE3(adjointSE3(T) * xi);
    EXPECT_LT((lhs.matrix() - rhs.matrix()).norm(), 1e-9);
  }
}

TEST(Se3, LeftJacobianInverseIsTheInverse) {
  const Eigen::Vector3d phi(0.5, 0.1, -0.7);
  EXPECT_LT(
      (leftJacobianSO3(phi) * leftJacobianInverseSO3(phi) - Eigen::Matrix3d::Identity()).norm(),
      1e-12);
}

TEST(Se3, RotationAngleIsAccurateForTinyAndLargeAngles) {
  EXPECT_NEAR(rotationAngleRad(expSO3(Eigen::Vector3d(1e-8, 0, 0))), 1e-8, 1e-14);
  EXPECT_NEAR(rotationAngleRad(expSO3(Eigen::Vector3d(0, 2.5, 0))), 2.5, 1e-12);
}

}  // namespace
}  // namespace slamd
