#include "slamd/planes/plane_registration.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "plain_corridor.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "test_data.hpp"
#include "tum_frames.hpp"

namespace slamd::planes {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct PoseError {
  double translation_m = 0.0;
  double rotation_deg = 0.0;
};

PoseError poseError(const SE3& estimate, const SE3& truth) {
  const SE3 delta = truth.inverse() * estimate;
  return {delta.translation().norm(), rotationAngleRad(delta.linear()) * 180.0 / kPi};
}

/// The error with its components along the reported degenerate directions removed: the data
/// say nothing there, and the estimate stays at the guess by design.
PoseError observableError(const IcpResult& result, const SE3& truth) {
  const Vector6d error =
      observableProjector(result) * logSE3(truth.inverse() * result.T_target_source);
  return {error.head<3>().norm(), error.tail<3>().norm() * 180.0 / kPi};
}

/// Both registrations of one frame pair, from the identity, against the true motion.
struct PairResult {
  IcpResult planes;
  IcpResult clouds;
  PoseError planes_error;
  PoseError clouds_error;
  PoseError planes_observable_error;  ///< without the degenerate directions
  PoseError clouds_observable_error;
  PoseError motion;  ///< the true motion's size
};

PairResult registerPair(const RgbdFrame& source, const RgbdFrame& target,
                        const SE3& T_target_source_true) {
  PlaneSegmenter source_segmenter;
  PlaneSegmenter target_segmenter;
  const PlaneSegmentation& source_planes = source_segmenter.segment(source);
  const PlaneSegmentation& target_planes = target_segmenter.segment(target);
  PairResult out;
  out.planes = registerPlanes(source_planes, target_planes, source.intrinsics, SE3::Identity());
  out.clouds = registerClouds(source.depth_m, target.depth_m, source.intrinsics, SE3::Identity());
  out.planes_error = poseError(out.planes.T_target_source, T_target_source_true);
  out.clouds_error = poseError(out.clouds.T_target_source, T_target_source_true);
  out.planes_observable_error = observableError(out.planes, T_target_source_true);
  out.clouds_observable_error = observableError(out.clouds, T_target_source_true);
  out.motion = poseError(SE3::Identity(), T_target_source_true);
  return out;
}

void print(const char* name, const PairResult& r) {
  std::printf(
      "%s: motion %.1f mm %.2f deg; planes %.2f mm %.3f deg (%d points, %d correspondences, %d "
      "plane matches, %d iterations, %zu free directions); whole cloud %.2f mm %.3f deg (%d "
      "points, %d iterations, %zu free directions)\n",
      name, 1e3 * r.motion.translation_m, r.motion.rotation_deg, 1e3 * r.planes_error.translation_m,
      r.planes_error.rotation_deg, r.planes.source_points, r.planes.correspondences,
      r.planes.plane_matches, r.planes.iterations, r.planes.degenerate_directions.size(),
      1e3 * r.clouds_error.translation_m, r.clouds_error.rotation_deg, r.clouds.source_points,
      r.clouds.iterations, r.clouds.degenerate_directions.size());
}

// ---------------------------------------------------------------------------------------------
// slamd's rendered room: consecutive frames and frames 10 apart, exact renders and with the
// Kinect v1 sensor model (noise, and depth quantised in steps of 1-4.5 cm at 2-4 m).

TEST(PlaneRegistration, RecoversTheMotionBetweenRoomFrames) {
  for (const bool exact : {true, false}) {
    Config config;
    if (exact) config.applyOverride("synthetic.sensor.exact=true");
    const SyntheticSource source("room", SyntheticConfig::load(config));
    const Trajectory truth = *source.groundTruth();
    for (const auto& [first, second] :
         std::vector<std::pair<int, int>>{{10, 11}, {10, 20}, {60, 70}}) {
      const RgbdFramePtr a = source.renderFrame(first);
      const RgbdFramePtr b = source.renderFrame(second);
      const SE3 T_b_a = truth[static_cast<std::size_t>(second)].T_world_camera.inverse() *
                        truth[static_cast<std::size_t>(first)].T_world_camera;
      const PairResult r = registerPair(*a, *b, T_b_a);
      const std::string name = std::string(exact ? "room (exact) " : "room (Kinect model) ") +
                               std::to_string(first) + "->" + std::to_string(second);
      print(name.c_str(), r);
      ASSERT_TRUE(r.planes.ok) << r.planes.error;
      // Frame 10 faces one wall above the floor (its other planes are parallel to these two):
      // the translation along both is free for planes. Frame 60 sees two walls and the floor.
      EXPECT_EQ(r.planes.degenerate_directions.size(), first == 10 ? 1u : 0u) << name;
      EXPECT_EQ(r.planes.covariance.has_value(), r.planes.degenerate_directions.empty());
      EXPECT_LT(r.planes_observable_error.translation_m, exact ? 0.003 : 0.01) << name;
      EXPECT_LT(r.planes_observable_error.rotation_deg, exact ? 0.2 : 0.5) << name;
      // Far fewer points than the whole cloud (paper 000's point).
      EXPECT_LT(r.planes.source_points * 20, r.clouds.source_points);
      // Whole-cloud ICP uses the room's objects too (nothing is free for it) and is exact on
      // exact renders; with the sensor model its per-pixel normals come from quantised depth
      // and it slides by centimetres to decimetres (docs/planes.md), which plane fits average
      // out.
      if (exact) {
        ASSERT_TRUE(r.clouds.ok) << r.clouds.error;
        EXPECT_LT(r.clouds_error.translation_m, 0.002) << name;
        EXPECT_LT(r.clouds_error.rotation_deg, 0.05) << name;
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// A plain corridor: walls, floor and ceiling only, each a flat colour. Planes fix five degrees
// of freedom; the translation along the corridor is free (test::renderCorridor).

TEST(PlaneRegistration, AlongAPlainCorridorTheFreeTranslationIsReportedAndLeftAtTheGuess) {
  const SE3 T_world_source = SE3::Identity();
  SE3 T_world_target = SE3::Identity();
  T_world_target.linear() =
      Eigen::AngleAxisd(2.0 * kPi / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T_world_target.translation() = Eigen::Vector3d(0.03, -0.02, 0.20);
  const RgbdFrame source = test::renderCorridor(T_world_source);
  const RgbdFrame target = test::renderCorridor(T_world_target);
  const SE3 T_target_source = T_world_target.inverse() * T_world_source;
  PlaneSegmenter source_segmenter;
  PlaneSegmenter target_segmenter;
  const PlaneSegmentation& source_planes = source_segmenter.segment(source);
  const PlaneSegmentation& target_planes = target_segmenter.segment(target);
  ASSERT_EQ(source_planes.planes.size(), 4u);
  ASSERT_EQ(target_planes.planes.size(), 4u);
  // The corridor's axis in the target camera's frame: the free direction of T_target_source's
  // right perturbation is the source frame's z axis.
  const Eigen::Vector3d axis_source = Eigen::Vector3d::UnitZ();

  for (const double guess_along_m : {0.0, 0.5}) {
    SCOPED_TRACE("guess along the corridor " + std::to_string(guess_along_m) + " m");
    // The guess: no motion, except a chosen distance along the corridor.
    const SE3 guess = SE3(Eigen::Translation3d(0.0, 0.0, -guess_along_m));
    for (const bool planes : {true, false}) {
      SCOPED_TRACE(planes ? "plane ICP" : "whole-cloud ICP");
      const IcpResult result =
          planes ? registerPlanes(source_planes, target_planes, source.intrinsics, guess)
                 : registerClouds(source.depth_m, target.depth_m, source.intrinsics, guess);
      ASSERT_TRUE(result.ok) << result.error;
      ASSERT_EQ(result.degenerate_directions.size(), 1u);
      const Vector6d& free = result.degenerate_directions.front();
      EXPECT_GT(std::abs(free.head<3>().dot(axis_source)), 0.999);
      EXPECT_FALSE(result.covariance.has_value());
      // Everything but the free direction is recovered; along it the guess is kept.
      const SE3 delta = T_target_source.inverse() * result.T_target_source;
      const Eigen::Vector3d error_source = delta.translation();
      EXPECT_LT((error_source - error_source.dot(axis_source) * axis_source).norm(), 0.002);
      EXPECT_LT(rotationAngleRad(delta.linear()) * 180.0 / kPi, 0.1);
      // Kept to first order: a step's rotation turns the estimate slightly (0.5 mm here).
      const double along_m = result.T_target_source.inverse().translation().dot(axis_source);
      EXPECT_NEAR(along_m, guess_along_m, 0.002);
      // The information matrix says the same: nothing along the free direction.
      EXPECT_LT(free.transpose() * result.information * free, 1e-6 * result.information.trace());
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Real data: TUM RGB-D fr1/xyz.

TEST(PlaneRegistration, RecoversTheMotionBetweenTumFr1XyzFrames) {
  const auto dir = test::findDataset("tum_fr1_xyz");
  if (!dir) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  for (const auto& [first, second] :
       std::vector<std::pair<std::size_t, std::size_t>>{{0, 1}, {0, 5}, {300, 301}, {300, 305}}) {
    const std::optional<test::TumFrame> a = test::loadTumFrame(*dir, first);
    const std::optional<test::TumFrame> b = test::loadTumFrame(*dir, second);
    ASSERT_TRUE(a && b);
    const SE3 T_b_a = b->T_world_camera.inverse() * a->T_world_camera;
    const PairResult r = registerPair(a->frame, b->frame, T_b_a);
    const std::string name = "fr1/xyz " + std::to_string(first) + "->" + std::to_string(second);
    print(name.c_str(), r);
    ASSERT_TRUE(r.planes.ok) << r.planes.error;
    ASSERT_TRUE(r.clouds.ok) << r.clouds.error;
    // Both agree with each other (within about 1 mm and 0.15 deg) far better than with the
    // motion capture; why that differs by up to 1.3 deg is not known (the images are used
    // without undistortion here).
    EXPECT_LT(r.planes_error.translation_m, 0.015) << name;
    EXPECT_LT(r.planes_error.rotation_deg, 1.6) << name;
    EXPECT_LT(r.clouds_error.translation_m, 0.015) << name;
    EXPECT_LT(r.clouds_error.rotation_deg, 1.6) << name;
    EXPECT_LT(r.planes_error.translation_m, r.clouds_error.translation_m + 0.002) << name;
    EXPECT_LT(r.planes_error.rotation_deg, r.clouds_error.rotation_deg + 0.25) << name;
  }
}

// ---------------------------------------------------------------------------------------------
// Bad input.

TEST(PlaneRegistration, BadInputGivesAnErrorNotAnEstimate) {
  const RgbdFrame frame = test::renderCorridor(SE3::Identity());
  PlaneSegmenter segmenter;
  const PlaneSegmentation planes = segmenter.segment(frame);
  const CameraIntrinsics& k = frame.intrinsics;
  SE3 not_finite = SE3::Identity();
  not_finite.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(registerPlanes(planes, planes, k, not_finite).ok);
  EXPECT_FALSE(registerClouds(frame.depth_m, frame.depth_m, k, not_finite).ok);
  EXPECT_FALSE(registerPlanes(PlaneSegmentation{}, planes, k, SE3::Identity()).ok);
  PlaneSegmentation no_labels = planes;
  no_labels.labels = cv::Mat();
  EXPECT_FALSE(registerPlanes(planes, no_labels, k, SE3::Identity()).ok);
  cv::Mat wrong_type;
  frame.depth_m.convertTo(wrong_type, CV_64FC1);
  EXPECT_FALSE(registerClouds(wrong_type, frame.depth_m, k, SE3::Identity()).ok);
  EXPECT_FALSE(registerClouds(frame.depth_m, frame.depth_m(cv::Rect(0, 0, 100, 100)).clone(), k,
                              SE3::Identity())
                   .ok);
  const cv::Mat no_depth(k.height, k.width, CV_32FC1, cv::Scalar(0.0f));
  const IcpResult empty = registerClouds(no_depth, no_depth, k, SE3::Identity());
  EXPECT_FALSE(empty.ok);
  EXPECT_FALSE(empty.error.empty());
  IcpParams bad;
  bad.max_iterations = 0;
  EXPECT_FALSE(bad.validationError().empty());
  EXPECT_FALSE(registerPlanes(planes, planes, k, SE3::Identity(), bad).ok);
  // Registering a frame with itself from the identity stays there.
  const IcpResult same = registerPlanes(planes, planes, k, SE3::Identity());
  ASSERT_TRUE(same.ok) << same.error;
  EXPECT_LT(same.T_target_source.translation().norm(), 1e-9);
}

}  // namespace
}  // namespace slamd::planes
