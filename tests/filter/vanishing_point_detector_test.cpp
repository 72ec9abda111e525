#include "slamd/filter/vanishing_point_detector.hpp"

#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "corridor_scene.hpp"
#include "slamd/common/config.hpp"

namespace slamd {
namespace {

using filter_test::corridorVanishingPoint;
using filter_test::renderCorridor;
using filter_test::yawPitchRoll;

constexpr double kDeg = M_PI / 180.0;

struct CorridorPose {
  double yaw_deg, pitch_deg, roll_deg, x_m, y_m;
};

void expectCorridorWithin2Px(const std::string& detector_name, double image_scale = 0.5) {
  const CameraIntrinsics K;
  VanishingPointConfig config;
  config.segment_detector = detector_name;
  config.image_scale = image_scale;
  if (image_scale == 1.0) config.blur_kernel_px = 5;
  VanishingPointDetector detector(K, config);
  const CorridorPose poses[] = {{0, 0, 0, 0, 0},       {6, -3, 2, 0.3, 0},  {-9, 4, -3, -0.4, 0.2},
                                {15, 0, 0, 0.5, -0.1}, {-4, -7, 5, 0, 0.3}, {2, 8, -6, -0.6, -0.2}};
  unsigned seed = 1;
  for (const auto& p : poses) {
    SE3 T_world_camera = SE3::Identity();
    T_world_camera.linear() = yawPitchRoll(p.yaw_deg * kDeg, p.pitch_deg * kDeg, p.roll_deg * kDeg);
    T_world_camera.translation() = Eigen::Vector3d(p.x_m, p.y_m, 0.0);
    const cv::Mat gray = renderCorridor(K, T_world_camera, seed++);
    const Eigen::Vector2d expected = corridorVanishingPoint(K, T_world_camera.linear());
    const VanishingPoint vp = detector.detect(gray);
    ASSERT_EQ(vp.status, VanishingPointStatus::kOk)
        << vanishingPointStatusName(vp.status) << " yaw " << p.yaw_deg;
    EXPECT_LT((vp.pixel - expected).norm(), 2.0)
        << detector_name << " yaw " << p.yaw_deg << " pitch " << p.pitch_deg << ": got "
        << vp.pixel.transpose() << " expected " << expected.transpose();
    EXPECT_GE(vp.num_supporting_lines, config.min_supporting_lines);
    // The covariance is a real 2x2 covariance and its direction is K^-1 u normalised.
    EXPECT_GT(vp.pixel_covariance.determinant(), 0.0);
    EXPECT_NEAR(vp.direction_camera.norm(), 1.0, 1e-12);
    EXPECT_GT(vp.direction_camera.z(), 0.0);
    EXPECT_LT((K.project(vp.direction_camera) - vp.pixel).norm(), 1e-9);
    // Stated uncertainty is not absurd: the error is within 4 sigma (plus the floor).
    const Eigen::Vector2d e = vp.pixel - expected;
    EXPECT_LT(e.dot(vp.pixel_covariance.inverse() * e), 16.0 * 2.0);
  }
  EXPECT_EQ(detector.counters().detected, 6);
}

TEST(VanishingPointDetector, FindsSyntheticCorridorPointWithin2PxWithHough) {
  expectCorridorWithin2Px("hough");
}

TEST(VanishingPointDetector, FindsSyntheticCorridorPointWithin2PxWithHoughAtFullResolution) {
  expectCorridorWithin2Px("hough", 1.0);
}

TEST(VanishingPointDetector, FindsSyntheticCorridorPointWithin2PxWithLsd) {
  expectCorridorWithin2Px("lsd");
}

/// A pinwheel of grey sectors meeting at vp_px, each pixel the average over an 8x8 grid inside
/// it (a camera integrating over the pixel area), plus Gaussian noise: its edges are straight
/// lines through vp_px at sub-pixel positions. Sector edges avoid the image axes by 10+ degrees.
cv::Mat renderPinwheel(const CameraIntrinsics& K, const Eigen::Vector2d& vp_px, unsigned seed) {
  const double edges_deg[] = {15.0,  40.0,  62.0,  118.0, 145.0, 165.0,
                              197.0, 222.0, 250.0, 290.0, 318.0, 340.0};
  const std::uint8_t shades[] = {60, 170, 90, 200, 70, 150, 100, 210, 80, 180, 110, 190};
  constexpr int kSub = 8;
  cv::Mat gray(K.height, K.width, CV_8UC1);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 2.0);
  for (int r = 0; r < K.height; ++r) {
    for (int c = 0; c < K.width; ++c) {
      double sum = 0.0;
      for (int i = 0; i < kSub; ++i) {
        for (int j = 0; j < kSub; ++j) {
          const double x = c - 0.5 + (j + 0.5) / kSub - vp_px.x();
          const double y = r - 0.5 + (i + 0.5) / kSub - vp_px.y();
          double a = std::atan2(y, x) / kDeg;
          if (a < 0.0) a += 360.0;
          int sector = 0;
          while (sector < 12 && a >= edges_deg[sector]) ++sector;
          sum += shades[sector % 12];
        }
      }
      gray.at<std::uint8_t>(r, c) =
          cv::saturate_cast<std::uint8_t>(sum / (kSub * kSub) + noise(rng));
    }
  }
  return gray;
}

// Canny edge pixels sit on the (half-resolution) pixel grid: lines through their centres put the
// point a few tenths of a pixel off. The sub-pixel refit on the full-resolution grey image must
// find it to a small fraction of a pixel.
TEST(VanishingPointDetector, SubPixelLineRefitLocatesPointToATenthOfAPixel) {
  const CameraIntrinsics K;
  VanishingPointConfig refined_config;
  VanishingPointConfig grid_config;
  grid_config.subpixel_lines = false;
  VanishingPointDetector refined(K, refined_config);
  VanishingPointDetector grid(K, grid_config);
  const Eigen::Vector2d points[] = {{341.37, 219.81}, {300.62, 262.29}, {318.05, 244.55}};
  double worst_refined = 0.0, sum_sq_grid = 0.0, sum_sq_refined = 0.0;
  unsigned seed = 7;
  for (const auto& vp_px : points) {
    const cv::Mat gray = renderPinwheel(K, vp_px, seed++);
    const VanishingPoint a = refined.detect(gray);
    const VanishingPoint b = grid.detect(gray);
    ASSERT_EQ(a.status, VanishingPointStatus::kOk);
    ASSERT_EQ(b.status, VanishingPointStatus::kOk);
    const double error_refined = (a.pixel - vp_px).norm();
    const double error_grid = (b.pixel - vp_px).norm();
    std::printf("point (%.2f, %.2f): error %.3f px refined, %.3f px on the edge-pixel grid\n",
                vp_px.x(), vp_px.y(), error_refined, error_grid);
    worst_refined = std::max(worst_refined, error_refined);
    sum_sq_refined += error_refined * error_refined;
    sum_sq_grid += error_grid * error_grid;
  }
  EXPECT_LT(worst_refined, 0.1);
  EXPECT_LT(sum_sq_refined, sum_sq_grid);
}

TEST(VanishingPointDetector, RecoversExactPointFromLinesWithOutliers) {
  const CameraIntrinsics K;
  VanishingPointDetector detector(K, VanishingPointConfig{});
  const Eigen::Vector2d vp(350.25, 210.75);
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * M_PI);
  std::uniform_real_distribution<double> dist(60.0, 300.0), len(40.0, 120.0);
  std::uniform_real_distribution<double> ux(0.0, 639.0), uy(0.0, 479.0);
  std::vector<LineSegment> segments;
  for (int i = 0; i < 30; ++i) {  // lines through vp
    const double a = angle(rng);
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    const Eigen::Vector2d p1 = vp + dist(rng) * dir;
    segments.push_back({p1, p1 + len(rng) * dir});
  }
  for (int i = 0; i < 30; ++i) {  // random outliers, pointing at least 10 degrees away from vp
    const Eigen::Vector2d p1(ux(rng), uy(rng));
    const double a = angle(rng);
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    const Eigen::Vector2d to_vp = (vp - p1).normalized();
    if (std::abs(dir.x() * to_vp.y() - dir.y() * to_vp.x()) < std::sin(10.0 * kDeg)) continue;
    segments.push_back({p1, p1 + len(rng) * dir});
  }
  const VanishingPoint result = detector.estimateFromSegments(segments);
  ASSERT_EQ(result.status, VanishingPointStatus::kOk);
  EXPECT_LT((result.pixel - vp).norm(), 1e-6);
  EXPECT_EQ(result.num_supporting_lines, 30);
  EXPECT_LT(result.rms_residual_px, 1.0);
}

TEST(VanishingPointDetector, RejectsBadImagesWithStatusAndCounts) {
  const CameraIntrinsics K;
  VanishingPointDetector detector(K, VanishingPointConfig{});
  EXPECT_EQ(detector.detect(cv::Mat()).status, VanishingPointStatus::kEmptyImage);
  EXPECT_EQ(detector.detect(cv::Mat(480, 640, CV_32FC1, cv::Scalar(0.5))).status,
            VanishingPointStatus::kWrongImageType);
  EXPECT_EQ(detector.detect(cv::Mat(480, 640, CV_8UC3, cv::Scalar(1, 2, 3))).status,
            VanishingPointStatus::kWrongImageType);
  EXPECT_EQ(detector.detect(cv::Mat(240, 320, CV_8UC1, cv::Scalar(9))).status,
            VanishingPointStatus::kWrongImageSize);
  EXPECT_EQ(detector.counters().bad_input, 4);
  EXPECT_EQ(detector.detect(cv::Mat(480, 640, CV_8UC1, cv::Scalar(128))).status,
            VanishingPointStatus::kTooFewLines);
  EXPECT_EQ(detector.counters().not_detected, 1);
  EXPECT_EQ(detector.counters().images, 5);
}

TEST(VanishingPointDetector, RejectsPointFarOutsideTheImage) {
  const CameraIntrinsics K;
  VanishingPointDetector detector(K, VanishingPointConfig{});
  const Eigen::Vector2d far(5000.0, 240.0);
  std::vector<LineSegment> segments;
  for (int i = 0; i < 10; ++i) {
    const Eigen::Vector2d p1(100.0, 40.0 + 40.0 * i);
    const Eigen::Vector2d dir = (far - p1).normalized();
    segments.push_back({p1, p1 + 200.0 * dir});
  }
  EXPECT_EQ(detector.estimateFromSegments(segments).status, VanishingPointStatus::kOutsideImage);
}

TEST(VanishingPointDetector, RejectsParallelAndDegenerateSegments) {
  const CameraIntrinsics K;
  VanishingPointDetector detector(K, VanishingPointConfig{});
  std::vector<LineSegment> parallel;
  for (int i = 0; i < 10; ++i) {
    parallel.push_back(
        {Eigen::Vector2d(50.0, 10.0 + 30 * i), Eigen::Vector2d(250.0, 60.0 + 30 * i)});
  }
  EXPECT_NE(detector.estimateFromSegments(parallel).status, VanishingPointStatus::kOk);
  std::vector<LineSegment> broken(6, LineSegment{Eigen::Vector2d(1, 1), Eigen::Vector2d(1, 1)});
  broken.push_back({Eigen::Vector2d(NAN, 1), Eigen::Vector2d(5, 5)});
  EXPECT_EQ(detector.estimateFromSegments(broken).status, VanishingPointStatus::kTooFewLines);
}

TEST(VanishingPointDetector, DropsAxisParallelSegments) {
  const CameraIntrinsics K;
  VanishingPointConfig config;
  VanishingPointDetector detector(K, config);
  SE3 T = SE3::Identity();
  T.linear() = yawPitchRoll(3 * kDeg, -2 * kDeg, 0.0);
  ASSERT_EQ(detector.detect(renderCorridor(K, T, 7)).status, VanishingPointStatus::kOk);
  const double sine = std::sin(config.axis_parallel_angle_deg * kDeg);
  for (const auto& s : detector.segments()) {
    const Eigen::Vector2d d = (s.p2_px - s.p1_px).normalized();
    EXPECT_GT(std::abs(d.x()), sine);
    EXPECT_GT(std::abs(d.y()), sine);
  }
}

TEST(VanishingPointConfig, LoadsDefaultsAndRejectsBadValues) {
  Config empty;
  const FilterConfig defaults = FilterConfig::load(empty);
  EXPECT_TRUE(defaults.enabled);
  EXPECT_DOUBLE_EQ(defaults.gate_chi2, 5.99);
  EXPECT_EQ(defaults.vp.segment_detector, "hough");
  EXPECT_EQ(defaults.reanchor_detections, 5);
  EXPECT_EQ(defaults.reanchor_min_updates, 100);

  Config custom = Config::fromYamlString(
      "filter:\n  gate_chi2: 9.21\n  vp:\n    segment_detector: lsd\n    ransac_iterations: 50\n");
  const FilterConfig loaded = FilterConfig::load(custom);
  EXPECT_DOUBLE_EQ(loaded.gate_chi2, 9.21);
  EXPECT_EQ(loaded.vp.segment_detector, "lsd");
  EXPECT_EQ(loaded.vp.ransac_iterations, 50);

  Config bad_range;
  bad_range.set("filter.gate_chi2", "-1");
  EXPECT_THROW(FilterConfig::load(bad_range), ConfigError);
  Config bad_reanchor;
  bad_reanchor.set("filter.reanchor_detections", "-1");
  EXPECT_THROW(FilterConfig::load(bad_reanchor), ConfigError);
  Config bad_type;
  bad_type.set("filter.vp.hough_threshold", "many");
  EXPECT_THROW(FilterConfig::load(bad_type), ConfigError);
  Config bad_order;
  bad_order.set("filter.vp.canny_low", "200");
  bad_order.set("filter.vp.canny_high", "100");
  EXPECT_THROW(FilterConfig::load(bad_order), ConfigError);
  Config bad_choice;
  bad_choice.set("filter.vp.segment_detector", "magic");
  EXPECT_THROW(FilterConfig::load(bad_choice), ConfigError);
}

}  // namespace
}  // namespace slamd
