#include "slamd/synth/motion.hpp"

#include <cmath>

#include <gtest/gtest.h>

#include "slamd/synth/renderer.hpp"
#include "synth_test_support.hpp"

namespace slamd::synth {
namespace {

const std::vector<MotionKind> kKinds = {MotionKind::kZigzag, MotionKind::kRandom,
                                        MotionKind::kRobot, MotionKind::kLoop};

class SceneMotions : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    for (const std::string& name : sceneNames()) {
      scenes_.push_back(makeScene(name, SceneParams(), 42));
    }
  }
  static void TearDownTestSuite() { scenes_.clear(); }
  static std::vector<Scene> scenes_;
};
std::vector<Scene> SceneMotions::scenes_;

TEST_F(SceneMotions, EveryTrajectoryKeepsTheCameraInFreeSpace) {
  for (const Scene& scene : scenes_) {
    for (MotionKind kind : kKinds) {
      CameraMotion motion(scene, kind, MotionParams(), 42);
      const Trajectory trajectory = sampleTrajectory(motion, motion.naturalFrameCount(), 0, 30.0);
      int outside = 0;
      for (const auto& pose : trajectory) {
        if (!scene.isFree(pose.T_world_camera.translation(), 0.25)) ++outside;
      }
      EXPECT_EQ(outside, 0) << scene.name << " " << motionKindName(kind);
    }
  }
}

TEST_F(SceneMotions, EveryTrajectoryIsSmoothAtThirtyHertz) {
  for (const Scene& scene : scenes_) {
    for (MotionKind kind : kKinds) {
      CameraMotion motion(scene, kind, MotionParams(), 42);
      const Trajectory trajectory = sampleTrajectory(motion, motion.naturalFrameCount(), 0, 30.0);
      double max_step_m = 0.0;
      double max_turn_rad = 0.0;
      for (std::size_t i = 1; i < trajectory.size(); ++i) {
        const SE3 delta = trajectory[i - 1].T_world_camera.inverse() * trajectory[i].T_world_camera;
        max_step_m = std::max(max_step_m, delta.translation().norm());
        max_turn_rad = std::max(max_turn_rad, rotationAngleRad(delta.linear()));
      }
      // Walking at 0.8 m/s is 2.7 cm per frame; turns stay below about 90 degrees per second.
      EXPECT_LT(max_step_m, 0.045) << scene.name << " " << motionKindName(kind);
      EXPECT_LT(max_turn_rad, 0.06) << scene.name << " " << motionKindName(kind);
    }
  }
}

TEST_F(SceneMotions, TheZigzagWalksDownTheCorridorAtAboutPointEightMetresPerSecond) {
  const Scene& corridor = scenes_[0];
  CameraMotion motion(corridor, MotionKind::kZigzag, MotionParams(), 42);
  const int frames = motion.naturalFrameCount();
  const Trajectory trajectory = sampleTrajectory(motion, frames, 0, 30.0);
  const double duration_s = (frames - 1) / 30.0;
  const double advance_m = trajectory.back().T_world_camera.translation().x() -
                           trajectory.front().T_world_camera.translation().x();
  EXPECT_NEAR(advance_m / duration_s, 0.8, 0.05);
  EXPECT_GT(advance_m, 25.0);  // most of the 30 m corridor
  double min_y = 1.0;
  double max_y = -1.0;
  for (const auto& pose : trajectory) {
    min_y = std::min(min_y, pose.T_world_camera.translation().y());
    max_y = std::max(max_y, pose.T_world_camera.translation().y());
  }
  EXPECT_GT(max_y - min_y, 0.4);  // a real lateral zigzag
}

TEST_F(SceneMotions, TheLoopReturnsToItsStart) {
  for (const Scene& scene : scenes_) {
    CameraMotion motion(scene, MotionKind::kLoop, MotionParams(), 42);
    const Trajectory trajectory = sampleTrajectory(motion, motion.naturalFrameCount(), 0, 30.0);
    const SE3 delta =
        trajectory.front().T_world_camera.inverse() * trajectory.back().T_world_camera;
    EXPECT_LT(delta.translation().norm(), 0.06) << scene.name;
    EXPECT_LT(rotationAngleRad(delta.linear()), 0.08) << scene.name;
  }
}

TEST_F(SceneMotions, TheRobotMovesInAPlaneWithALevelCamera) {
  for (const Scene& scene : scenes_) {
    MotionParams params;
    CameraMotion motion(scene, MotionKind::kRobot, params, 42);
    const Trajectory trajectory = sampleTrajectory(motion, motion.naturalFrameCount(), 0, 30.0);
    for (const auto& pose : trajectory) {
      EXPECT_NEAR(pose.T_world_camera.translation().z(), params.robot_height_m, 1e-12);
      // Optical axis horizontal, image x axis horizontal (no pitch, no roll).
      EXPECT_NEAR(pose.T_world_camera.linear().col(2).z(), 0.0, 1e-12);
      EXPECT_NEAR(pose.T_world_camera.linear().col(0).z(), 0.0, 1e-12);
    }
  }
}

TEST_F(SceneMotions, EveryTrajectoryLooksAtGeometryWithinSensorRange) {
  const CameraIntrinsics intrinsics = CameraIntrinsics().scaled(160, 120);
  for (const Scene& scene : scenes_) {
    Renderer renderer(scene, intrinsics);
    RenderOutput out;
    for (MotionKind kind : kKinds) {
      CameraMotion motion(scene, kind, MotionParams(), 42);
      const Trajectory trajectory = sampleTrajectory(motion, motion.naturalFrameCount(), 0, 30.0);
      double worst_in_range = 1.0;
      double min_depth = 100.0;
      const std::size_t stride = std::max<std::size_t>(1, trajectory.size() / 50);
      for (std::size_t i = 0; i < trajectory.size(); i += stride) {
        renderer.render(trajectory[i].T_world_camera, out);
        const cv::Mat in_range = (out.depth_m >= 0.5) & (out.depth_m <= 4.5);
        worst_in_range = std::min(
            worst_in_range, cv::countNonZero(in_range) / static_cast<double>(in_range.total()));
        double lo = 0.0;
        cv::minMaxLoc(out.depth_m, &lo);
        min_depth = std::min(min_depth, lo);
      }
      EXPECT_GT(worst_in_range, 0.4) << scene.name << " " << motionKindName(kind);
      EXPECT_GT(min_depth, 0.3) << scene.name << " " << motionKindName(kind);
    }
  }
}

TEST(Motion, ParsesTheTrajectoryNamesAndRejectsOthers) {
  EXPECT_EQ(parseMotionKind("zigzag"), MotionKind::kZigzag);
  EXPECT_EQ(parseMotionKind("loop"), MotionKind::kLoop);
  EXPECT_EQ(defaultMotionFor("corridor_loop"), MotionKind::kLoop);
  try {
    parseMotionKind("spiral");
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("spiral"), std::string::npos);
  }
}

TEST(Motion, FrameTimestampsFollowTheRateToTheMicrosecond) {
  EXPECT_EQ(frameUtime(1'000'000, 0, 30.0), 1'000'000);
  EXPECT_EQ(frameUtime(1'000'000, 1, 30.0), 1'033'333);
  EXPECT_EQ(frameUtime(1'000'000, 2, 30.0), 1'066'667);
  EXPECT_EQ(frameUtime(1'000'000, 30, 30.0), 2'000'000);
}

}  // namespace
}  // namespace slamd::synth
