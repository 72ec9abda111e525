#include "slamd/tracking/features.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

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

TEST(MoveDepthsToColourTime, KeepsThePixelAndTakesTheDepthAtTheColourImagesTime) {
  FeatureSet features;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  features.points = {Eigen::Vector3d(0.3, -0.2, 2.0), Eigen::Vector3d(nan, nan, nan),
                     Eigen::Vector3d(0.0, 0.0, 0.005)};
  // The camera moved 1 cm forward and turned 1 degree about y between the depth image and the
  // colour image: the depth camera sat 1 cm behind the colour camera.
  SE3 T_colour_depth = SE3::Identity();
  T_colour_depth.linear() = Eigen::AngleAxisd(-M_PI / 180.0, Eigen::Vector3d::UnitY()).matrix();
  T_colour_depth.translation() = Eigen::Vector3d(0.0, 0.0, -0.01);
  const Eigen::Vector3d before = features.points[0];
  const Eigen::Vector3d moved = T_colour_depth * features.points[0];
  moveDepthsToColourTime(T_colour_depth, features);
  // On the colour pixel's ray, at the depth the point has in the colour camera's frame.
  EXPECT_NEAR(features.points[0].z(), moved.z(), 1e-12);
  EXPECT_LT(features.points[0].z(), before.z() - 0.005);
  EXPECT_NEAR(features.points[0].x() / features.points[0].z(), before.x() / before.z(), 1e-12);
  EXPECT_NEAR(features.points[0].y() / features.points[0].z(), before.y() / before.z(), 1e-12);
  // No depth stays no depth; a point the motion would put behind the camera is left as it was.
  EXPECT_TRUE(std::isnan(features.points[1].z()));
  EXPECT_EQ(features.points[2], Eigen::Vector3d(0.0, 0.0, 0.005));
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

// Dark squares, each rotated, on a bright background, rendered with 8x8 samples per pixel (pixel
// (u, v) covers [u - 0.5, u + 0.5] x [v - 0.5, v + 0.5]) and blurred. Their corners are known to
// sub-pixel precision.
struct SquaresImage {
  cv::Mat gray;
  std::vector<cv::Point2d> corners;
};

SquaresImage renderSquares(cv::Point2d offset_px = {0.0, 0.0}) {
  SquaresImage out;
  out.gray = cv::Mat(240, 320, CV_8UC1);
  struct Square {
    cv::Point2d centre;
    double half_side, angle_rad;
  };
  std::vector<Square> squares;
  for (int j = 0; j < 4; ++j) {
    for (int i = 0; i < 6; ++i) {
      const Square s{
          {35.0 + 50.0 * i + 0.37 * j + offset_px.x, 35.0 + 55.0 * j + 0.61 * i + offset_px.y},
          10.0 + 0.3 * i,
          0.15 + 0.11 * i + 0.07 * j};
      squares.push_back(s);
      for (int c = 0; c < 4; ++c) {
        const double a = s.angle_rad + c * M_PI / 2.0 + M_PI / 4.0;
        const double r = s.half_side * std::sqrt(2.0);
        out.corners.emplace_back(s.centre.x + r * std::cos(a), s.centre.y + r * std::sin(a));
      }
    }
  }
  out.gray.setTo(220);
  constexpr int kSamples = 8;
  for (const Square& s : squares) {
    const int reach = static_cast<int>(std::ceil(s.half_side * std::sqrt(2.0))) + 1;
    const double c = std::cos(s.angle_rad), sn = std::sin(s.angle_rad);
    for (int v = static_cast<int>(s.centre.y) - reach; v <= static_cast<int>(s.centre.y) + reach;
         ++v) {
      for (int u = static_cast<int>(s.centre.x) - reach; u <= static_cast<int>(s.centre.x) + reach;
           ++u) {
        int inside = 0;
        for (int sy = 0; sy < kSamples; ++sy) {
          for (int sx = 0; sx < kSamples; ++sx) {
            const double dx = u - 0.5 + (sx + 0.5) / kSamples - s.centre.x;
            const double dy = v - 0.5 + (sy + 0.5) / kSamples - s.centre.y;
            inside += std::abs(c * dx + sn * dy) <= s.half_side &&
                      std::abs(-sn * dx + c * dy) <= s.half_side;
          }
        }
        out.gray.at<std::uint8_t>(v, u) =
            cv::saturate_cast<std::uint8_t>(220.0 - 180.0 * inside / (kSamples * kSamples));
      }
    }
  }
  // A camera's optics blur every edge over a pixel or two.
  cv::GaussianBlur(out.gray, out.gray, cv::Size(), 1.0);
  return out;
}

// The Foerstner point of a blurred corner lies inside it (the gradients of the pixels around the
// vertex point diagonally), so the test checks what odometry needs: the refined corner moves with
// the image, to a fraction of a pixel. It also agrees with OpenCV's cornerSubPix, which computes
// the same point and which the tracker used before.
TEST(RefineCorner, MovesWithTheImageAndAgreesWithCornerSubPix) {
  const SquaresImage image = renderSquares();
  const cv::Point2d shift_px(0.37, -0.28);
  const SquaresImage shifted = renderSquares(shift_px);
  std::vector<double> shift_errors_px;
  double worst_opencv_difference_px = 0.0;
  for (const cv::Point2d& corner : image.corners) {
    const cv::Point2f start(static_cast<float>(std::round(corner.x)),
                            static_cast<float>(std::round(corner.y)));
    cv::Point2f refined, refined_shifted;
    ASSERT_TRUE(refineCorner(image.gray, start, refined)) << "corner " << corner;
    ASSERT_TRUE(refineCorner(shifted.gray, start, refined_shifted)) << "corner " << corner;
    const cv::Point2d moved_px = cv::Point2d(refined_shifted) - cv::Point2d(refined);
    shift_errors_px.push_back(std::hypot(moved_px.x - shift_px.x, moved_px.y - shift_px.y));
    std::vector<cv::Point2f> opencv{start};
    cv::cornerSubPix(image.gray, opencv, cv::Size(2, 2), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 6, 0.02));
    worst_opencv_difference_px =
        std::max(worst_opencv_difference_px,
                 static_cast<double>(std::hypot(opencv[0].x - refined.x, opencv[0].y - refined.y)));
  }
  std::sort(shift_errors_px.begin(), shift_errors_px.end());
  // Integer positions do not move at all: an error of the whole shift, 0.46 px.
  EXPECT_LT(shift_errors_px[shift_errors_px.size() / 2], 0.1) << "median";
  EXPECT_LT(shift_errors_px.back(), 0.25) << "worst";
  EXPECT_LT(worst_opencv_difference_px, 0.01);
}

TEST(RefineCorner, RefusesFlatPatchesAndTheBorder) {
  const SquaresImage image = renderSquares();
  cv::Point2f refined;
  EXPECT_FALSE(refineCorner(image.gray, cv::Point2f(5.0f, 120.0f), refined));  // background
  EXPECT_FALSE(refineCorner(image.gray, cv::Point2f(1.0f, 1.0f), refined));
  EXPECT_FALSE(refineCorner(image.gray, cv::Point2f(318.5f, 100.0f), refined));
  EXPECT_FALSE(refineCorner(cv::Mat(), cv::Point2f(50.0f, 50.0f), refined));
}

/// Smooth random texture: every 9x9 patch has gradients in both directions.
cv::Mat randomTexture(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> level(0, 255);
  cv::Mat noise(height, width, CV_8UC1);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u)
      noise.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(level(rng));
  }
  cv::Mat smooth;
  cv::GaussianBlur(noise, smooth, cv::Size(), 3.0);
  cv::normalize(smooth, smooth, 0, 255, cv::NORM_MINMAX);
  return smooth;
}

TEST(AlignPatch, FindsASubpixelShiftAndAMagnifiedView) {
  const cv::Mat templ = randomTexture(120, 100, 7);
  const cv::Point2f templ_px(60.0f, 50.0f);
  // A view shifted by (2.3, -1.6) px, started from the nearest integer guess off by (0.3, 0.4).
  {
    const cv::Matx23d shift(1, 0, 2.3, 0, 1, -1.6);
    cv::Mat image;
    cv::warpAffine(templ, image, shift, templ.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
    cv::Point2f aligned;
    ASSERT_TRUE(
        alignPatch(templ, templ_px, image, templ_px + cv::Point2f(2.0f, -2.0f), 3.0, aligned));
    EXPECT_NEAR(aligned.x, 62.3, 0.1);
    EXPECT_NEAR(aligned.y, 48.4, 0.1);
  }
  // The same place seen 1.15 times larger around templ_px (the camera came closer): only the
  // warped template aligns.
  {
    const double scale = 1.15;
    const cv::Matx23d magnify(scale, 0, (1 - scale) * 60.0 + 1.4, 0, scale,
                              (1 - scale) * 50.0 + 0.7);
    cv::Mat image;
    cv::warpAffine(templ, image, magnify, templ.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
    const cv::Matx33d ref_from_curr(1 / scale, 0, 0, 0, 1 / scale, 0, 0, 0, 1);
    cv::Point2f aligned;
    ASSERT_TRUE(alignPatch(templ, templ_px, image, templ_px + cv::Point2f(1.0f, 1.0f), 3.0, aligned,
                           ref_from_curr));
    EXPECT_NEAR(aligned.x, 61.4, 0.1);
    EXPECT_NEAR(aligned.y, 50.7, 0.1);
  }
  // An unrelated image does not correlate, and a shift beyond max_shift_px is refused.
  {
    const cv::Mat other = randomTexture(120, 100, 8);
    cv::Point2f aligned;
    EXPECT_FALSE(alignPatch(templ, templ_px, other, templ_px, 3.0, aligned));
    const cv::Matx23d shift(1, 0, 2.3, 0, 1, -1.6);
    cv::Mat image;
    cv::warpAffine(templ, image, shift, templ.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
    EXPECT_FALSE(alignPatch(templ, templ_px, image, templ_px, 1.0, aligned));
  }
}

}  // namespace
}  // namespace slamd
