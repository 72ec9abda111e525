#include <cmath>

#include <gtest/gtest.h>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/rgbd_frame.hpp"

namespace slamd {
namespace {

CameraIntrinsics fr1() {
  CameraIntrinsics k;
  k.fx = 517.3;
  k.fy = 516.5;
  k.cx = 318.6;
  k.cy = 255.3;
  return k;
}

TEST(CameraIntrinsics, ProjectInvertsBackProject) {
  const CameraIntrinsics k = fr1();
  const Eigen::Vector3d p = k.backProject(100.25, 400.5, 2.5);
  EXPECT_DOUBLE_EQ(p.z(), 2.5);
  const Eigen::Vector2d uv = k.project(p);
  EXPECT_NEAR(uv.x(), 100.25, 1e-12);
  EXPECT_NEAR(uv.y(), 400.5, 1e-12);
}

TEST(CameraIntrinsics, ScalingKeepsRaysThroughPixelCentres) {
  const CameraIntrinsics k = fr1();
  const CameraIntrinsics half = k.scaled(320, 240);
  EXPECT_DOUBLE_EQ(half.fx, k.fx / 2);
  // Pixel (2x+0.5, 2y+0.5) at full resolution is pixel (x, y) at half resolution.
  const Eigen::Vector3d ray_full = k.ray(2 * 10 + 0.5, 2 * 20 + 0.5);
  const Eigen::Vector3d ray_half = half.ray(10, 20);
  EXPECT_LT((ray_full - ray_half).norm(), 1e-12);
}

TEST(CameraIntrinsics, ValidationNamesTheProblem) {
  CameraIntrinsics k = fr1();
  EXPECT_EQ(k.validationError(), "");
  k.fx = -1;
  EXPECT_NE(k.validationError().find("focal"), std::string::npos);
  k = fr1();
  k.width = 0;
  EXPECT_NE(k.validationError().find("size"), std::string::npos);
}

TEST(RgbdFrame, DepthConversionMapsZeroToNanAndBack) {
  cv::Mat raw(2, 3, CV_16UC1);
  raw.at<std::uint16_t>(0, 0) = 0;
  raw.at<std::uint16_t>(0, 1) = 5000;
  raw.at<std::uint16_t>(0, 2) = 12345;
  raw.at<std::uint16_t>(1, 0) = 65535;
  raw.at<std::uint16_t>(1, 1) = 1;
  raw.at<std::uint16_t>(1, 2) = 0;
  const cv::Mat depth_m = depthRawToMeters(raw, 5000.0);
  EXPECT_TRUE(std::isnan(depth_m.at<float>(0, 0)));
  EXPECT_FLOAT_EQ(depth_m.at<float>(0, 1), 1.0f);
  EXPECT_FLOAT_EQ(depth_m.at<float>(0, 2), 12345.0f / 5000.0f);
  const cv::Mat back = depthMetersToRaw(depth_m, 5000.0);
  EXPECT_EQ(cv::countNonZero(back != raw), 0);
}

TEST(RgbdFrame, MetersToRawRejectsNonFiniteNegativeAndOverflow) {
  cv::Mat depth_m(1, 4, CV_32FC1);
  depth_m.at<float>(0, 0) = std::numeric_limits<float>::quiet_NaN();
  depth_m.at<float>(0, 1) = -1.0f;
  depth_m.at<float>(0, 2) = std::numeric_limits<float>::infinity();
  depth_m.at<float>(0, 3) = 100.0f;  // 500000 raw at scale 5000: out of uint16 range
  EXPECT_EQ(cv::countNonZero(depthMetersToRaw(depth_m, 5000.0)), 0);
}

TEST(RgbdFrame, ValidationCatchesWrongTypesAndSizes) {
  RgbdFrame frame;
  frame.intrinsics = fr1();
  frame.depth_m = cv::Mat(480, 640, CV_32FC1, cv::Scalar(1.0));
  frame.color_bgr = cv::Mat(480, 640, CV_8UC3, cv::Scalar(1, 2, 3));
  EXPECT_EQ(frame.validationError(), "");
  frame.color_bgr = cv::Mat(240, 320, CV_8UC3);
  EXPECT_NE(frame.validationError(), "");
  frame.color_bgr = cv::Mat(480, 640, CV_8UC1);
  EXPECT_NE(frame.validationError(), "");
  frame.color_bgr = cv::Mat(480, 640, CV_8UC3);
  frame.depth_m = cv::Mat(480, 640, CV_16UC1);
  EXPECT_NE(frame.validationError().find("CV_32FC1"), std::string::npos);
}

}  // namespace
}  // namespace slamd
