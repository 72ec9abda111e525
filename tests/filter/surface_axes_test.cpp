#include "slamd/filter/surface_axes.hpp"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "corridor_scene.hpp"
#include "slamd/filter/pose_ekf.hpp"

namespace slamd {
namespace {

using filter_test::renderCorridorDepth;
using filter_test::yawPitchRoll;

constexpr double kRadToDeg = 180.0 / M_PI;

SE3 tiltedCamera() {
  SE3 T = SE3::Identity();
  T.linear() = yawPitchRoll(0.17, -0.09, 0.05);  // about 10, -5 and 3 degrees
  T.translation() = Eigen::Vector3d(0.2, 0.3, 0.0);
  return T;
}

/// Angle (degrees) between the axis seen in the camera and the nearest world axis, and the
/// squared error normalised by the reported covariance (2 DoF), both for the world axis `k`.
struct AxisError {
  int world_axis = -1;
  double angle_deg = 0.0;
  double normalised_sq = 0.0;
};

AxisError axisError(const SurfaceAxis& axis, const Eigen::Matrix3d& R_world_camera) {
  AxisError e;
  const Eigen::Vector3d in_world = R_world_camera * axis.direction_camera;
  in_world.cwiseAbs().maxCoeff(&e.world_axis);
  Eigen::Vector3d truth_world = Eigen::Vector3d::Unit(e.world_axis);
  if (truth_world.dot(in_world) < 0.0) truth_world = -truth_world;
  const Eigen::Vector3d truth_camera = R_world_camera.transpose() * truth_world;
  e.angle_deg = std::acos(std::min(1.0, truth_camera.dot(axis.direction_camera))) * kRadToDeg;
  const Eigen::Vector2d t = PoseEkf::tangentBasis(axis.direction_camera).transpose() * truth_camera;
  e.normalised_sq = t.dot(axis.covariance.inverse() * t);
  return e;
}

TEST(SurfaceAxisDetector, FindsTheCorridorsFloorAndWallAxesExactly) {
  const CameraIntrinsics K;
  const SE3 T = tiltedCamera();
  SurfaceAxisDetector detector(SurfaceAxesConfig{}, K);
  const SurfaceAxes result = detector.detect(renderCorridorDepth(K, T));
  ASSERT_EQ(result.status, SurfaceAxesStatus::kOk);
  // Walls (world x) and floor/ceiling (world y); the corridor's own axis has no plane in range.
  ASSERT_EQ(result.axes.size(), 2u);
  bool seen[3] = {false, false, false};
  for (const SurfaceAxis& axis : result.axes) {
    const AxisError e = axisError(axis, T.linear());
    seen[e.world_axis] = true;
    EXPECT_LT(e.angle_deg, 0.01) << "world axis " << e.world_axis;
    EXPECT_GE(axis.num_cells, 12);
    EXPECT_NEAR(axis.direction_camera.norm(), 1.0, 1e-12);
  }
  EXPECT_TRUE(seen[0] && seen[1]) << "walls and floor";
  EXPECT_EQ(detector.counters().detected, 1);
}

TEST(SurfaceAxisDetector, NoisyDepthGivesAxesWithinTheirCovariance) {
  // Over 20 noisy renderings, the axes stay well under half a degree and their errors normalised
  // by the reported covariance average about 2 (chi-square, 2 DoF); a covariance that ignored
  // the noise, or a fit biased by it (a 3D principal-component fit tilts towards the viewing
  // ray), would land far above.
  const CameraIntrinsics K;
  const SE3 T = tiltedCamera();
  SurfaceAxesConfig config;
  config.min_sigma_deg = 0.01;  // the covariance from the fits alone, not the calibration floor
  SurfaceAxisDetector detector(config, K);
  double sum_normalised = 0.0;
  int count = 0;
  for (unsigned seed = 1; seed <= 20; ++seed) {
    const SurfaceAxes result = detector.detect(renderCorridorDepth(K, T, seed));
    ASSERT_EQ(result.status, SurfaceAxesStatus::kOk);
    ASSERT_EQ(result.axes.size(), 2u);
    for (const SurfaceAxis& axis : result.axes) {
      const AxisError e = axisError(axis, T.linear());
      EXPECT_LT(e.angle_deg, 0.5);
      sum_normalised += e.normalised_sq;
      ++count;
    }
  }
  const double mean = sum_normalised / count;
  RecordProperty("mean_normalised_squared_error", std::to_string(mean));
  EXPECT_LT(mean, 4.0);
  EXPECT_GT(mean, 0.5);  // and not absurdly pessimistic either
}

TEST(SurfaceAxisDetector, BadInputGivesAStatusAndIsCounted) {
  const CameraIntrinsics K;
  SurfaceAxisDetector detector(SurfaceAxesConfig{}, K);
  EXPECT_EQ(detector.detect(cv::Mat()).status, SurfaceAxesStatus::kEmptyImage);
  EXPECT_EQ(detector.detect(cv::Mat(K.height, K.width, CV_16UC1, cv::Scalar(1000))).status,
            SurfaceAxesStatus::kWrongImageType);
  EXPECT_EQ(detector.detect(cv::Mat(100, 100, CV_32FC1, cv::Scalar(2.0f))).status,
            SurfaceAxesStatus::kWrongImageSize);
  const cv::Mat no_depth(K.height, K.width, CV_32FC1,
                         cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  EXPECT_EQ(detector.detect(no_depth).status, SurfaceAxesStatus::kNoPlanes);
  EXPECT_TRUE(detector.detect(no_depth).axes.empty());
  EXPECT_EQ(detector.counters().bad_input, 3);
  EXPECT_EQ(detector.counters().not_detected, 2);
}

TEST(SurfaceAxesConfig, RejectsAnEmptyDepthRange) {
  Config config;
  config.set("filter.axes.min_depth_m", "3.0");
  config.set("filter.axes.max_depth_m", "2.0");
  EXPECT_THROW(SurfaceAxesConfig::load(config), ConfigError);
}

}  // namespace
}  // namespace slamd
