#include "slamd/tracking/features.hpp"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

namespace slamd {
namespace {

// Depth image of a plane seen at a grazing angle: 1/z = a u + b v + c (exact for any plane in
// pixel coordinates of a pinhole camera). A corridor wall near the vanishing point looks like this.
constexpr double kA = 0.0042, kB = -0.0011, kC = 0.15;
double planeInverseDepth(double u, double v) { return kA * u + kB * v + kC; }

cv::Mat slantedPlaneDepth() {
  cv::Mat depth(120, 160, CV_32FC1);
  for (int v = 0; v < depth.rows; ++v) {
    for (int u = 0; u < depth.cols; ++u) {
      depth.at<float>(v, u) = static_cast<float>(1.0 / planeInverseDepth(u, v));
    }
  }
  return depth;
}

TrackingConfig wideDepthRange() {
  TrackingConfig config;
  config.min_depth_m = 0.1;
  config.max_depth_m = 20.0;
  return config;
}

TEST(DepthAtPixel, IsExactOnASlantedPlaneBetweenPixels) {
  const cv::Mat depth = slantedPlaneDepth();
  const TrackingConfig config = wideDepthRange();
  for (const auto& [u, v] :
       {std::pair{40.5, 30.5}, std::pair{80.25, 61.75}, std::pair{120.9, 90.1}}) {
    const double expected = 1.0 / planeInverseDepth(u, v);
    // Interpolating z itself is off by about 0.3 mm at these points; 1/z is exact (float storage).
    EXPECT_NEAR(depthAtPixel(depth, u, v, config), expected, 2e-6 * expected) << u << ", " << v;
  }
}

TEST(InverseDepthGradient, GivesThePlaneSlopeAndZeroAcrossADepthEdge) {
  cv::Mat depth = slantedPlaneDepth();
  const Eigen::Vector2d slope = inverseDepthGradient(depth, 60.0, 50.0, depth.at<float>(50, 60));
  EXPECT_NEAR(slope.x(), kA, 1e-6);
  EXPECT_NEAR(slope.y(), kB, 1e-6);
  // A nearer object two pixels to the right: the slope there is unknown.
  depth.at<float>(50, 62) = 0.5f * depth.at<float>(50, 62);
  EXPECT_EQ(inverseDepthGradient(depth, 60.0, 50.0, depth.at<float>(50, 60)),
            Eigen::Vector2d::Zero());
  // Missing depth, the border and a non-positive centre depth give zero as well.
  depth.at<float>(70, 60) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(inverseDepthGradient(depth, 60.0, 68.0, depth.at<float>(68, 60)),
            Eigen::Vector2d::Zero());
  EXPECT_EQ(inverseDepthGradient(depth, 1.0, 50.0, depth.at<float>(50, 1)),
            Eigen::Vector2d::Zero());
  EXPECT_EQ(inverseDepthGradient(depth, 60.0, 50.0, 0.0), Eigen::Vector2d::Zero());
  EXPECT_EQ(inverseDepthGradient(cv::Mat(), 60.0, 50.0, 2.0), Eigen::Vector2d::Zero());
}

}  // namespace
}  // namespace slamd
