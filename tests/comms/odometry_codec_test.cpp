// Odometry and vanishing-point messages carry the fields they document.

#include "slamd/comms/odometry_codec.hpp"

#include <cmath>
#include <cstdint>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace slamd {
namespace {

TEST(OdometryCodec, OdometryMessageCarriesTheFrameToFrameMotion) {
  OdometryResult odometry;
  odometry.utime = 2000;
  odometry.prev_utime = 1000;
  odometry.T_prev_curr = SE3::Identity();
  odometry.T_prev_curr.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).matrix();
  odometry.T_prev_curr.translation() = Eigen::Vector3d(0.1, -0.2, 0.3);
  odometry.covariance = Matrix6d::Zero();
  odometry.covariance(0, 5) = 7.0;
  odometry.status = OdometryStatus::kOk;
  odometry.stats.num_inliers = 42;
  odometry.is_keyframe = true;
  odometry.reference_keyframe_id = 5;
  const slamd::odometry_t msg = toOdometryMessage(odometry);
  EXPECT_EQ(msg.utime, 2000);
  EXPECT_EQ(msg.prev_utime, 1000);
  EXPECT_DOUBLE_EQ(msg.translation[1], -0.2);
  EXPECT_NEAR(msg.rotation[0], std::cos(0.15), 1e-12);  // w first
  EXPECT_NEAR(msg.rotation[3], std::sin(0.15), 1e-12);
  EXPECT_DOUBLE_EQ(msg.covariance[0 * 6 + 5], 7.0);  // row-major
  EXPECT_EQ(msg.status, static_cast<std::int8_t>(OdometryStatus::kOk));
  EXPECT_EQ(msg.num_inliers, 42);
  EXPECT_TRUE(msg.is_keyframe);
  EXPECT_EQ(msg.reference_keyframe_id, 5);
}

TEST(OdometryCodec, VanishingPointMessageCarriesTheDetectionAndTheUpdate) {
  VanishingPointReport report;
  report.detection.pixel = Eigen::Vector2d(320.5, 240.25);
  report.detection.num_supporting_lines = 12;
  report.update.landmark_id = 3;
  report.update.accepted = true;
  report.update.nis = 1.5;
  const slamd::vanishing_point_t msg = toVanishingPointMessage(77, report);
  EXPECT_EQ(msg.utime, 77);
  EXPECT_DOUBLE_EQ(msg.pixel[0], 320.5);
  EXPECT_DOUBLE_EQ(msg.pixel[1], 240.25);
  EXPECT_EQ(msg.num_supporting_lines, 12);
  EXPECT_EQ(msg.landmark_id, 3);
  EXPECT_TRUE(msg.accepted);
  EXPECT_DOUBLE_EQ(msg.mahalanobis_distance_sq, 1.5);
}

}  // namespace
}  // namespace slamd
