#include "slamd/backend/keyframe_trajectory.hpp"

#include <memory>

#include <gtest/gtest.h>

#include "slamd/backend/backend.hpp"

namespace slamd {
namespace {

SE3 poseAt(double x, double yaw_rad) {
  SE3 T = SE3::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, 0.0, 0.0);
  return T;
}

KeyframePtr keyframeAt(std::int64_t id, const SE3& T_world_camera) {
  auto keyframe = std::make_shared<Keyframe>();
  keyframe->id = id;
  keyframe->utime = 1'000'000 + id * 100'000;
  keyframe->T_world_camera = T_world_camera;
  return keyframe;
}

OdometryResult frameAt(Utime utime, const SE3& T_world_camera, std::int64_t reference_id,
                       const SE3& T_ref_curr) {
  OdometryResult r;
  r.utime = utime;
  r.T_world_camera = T_world_camera;
  r.reference_keyframe_id = reference_id;
  r.T_ref_curr = T_ref_curr;
  return r;
}

void expectNear(const SE3& actual, const SE3& expected) {
  EXPECT_LT((actual.translation() - expected.translation()).norm(), 1e-9);
  EXPECT_LT((actual.linear() - expected.linear()).norm(), 1e-9);
}

// Frames are stored against the keyframe they were measured from. When tracking takes one of the
// map's keyframes back (OdometryStats::used_map_keyframe), it measures against that keyframe at a
// new odometry pose: the frames from then on are stored against that pose, the earlier ones keep
// the pose the keyframe was made at.
TEST(KeyframeAnchoredTrajectory, AMapKeyframeTakenBackAnchorsTheFramesAfterItAtItsNewPose) {
  const SE3 T_world_kf0 = poseAt(0.0, 0.0);
  const SE3 T_world_kf1 = poseAt(1.0, 0.2);
  Backend backend(BackendConfig(), nullptr);
  backend.addKeyframe(keyframeAt(0, T_world_kf0));
  backend.addKeyframe(keyframeAt(1, T_world_kf1));
  KeyframeAnchoredTrajectory trajectory;
  trajectory.addKeyframe(keyframeAt(0, T_world_kf0));
  const SE3 T_kf0_early = poseAt(0.1, 0.0);
  trajectory.addFrame(frameAt(1'050'000, T_world_kf0 * T_kf0_early, 0, T_kf0_early));
  trajectory.addKeyframe(keyframeAt(1, T_world_kf1));

  // Back near keyframe 0 after drifting: odometry puts the frame at x = 0.35 while the
  // measurement against keyframe 0 says 0.2 from it, so keyframe 0 is now at x = 0.15 in
  // odometry.
  const SE3 T_kf0_curr = poseAt(0.2, 0.05);
  const SE3 T_world_curr = poseAt(0.35, 0.05);
  OdometryResult taken_back = frameAt(1'300'000, T_world_curr, 0, T_kf0_curr);
  taken_back.stats.used_map_keyframe = true;
  trajectory.addFrame(taken_back);
  const SE3 T_kf0_next = poseAt(0.25, 0.05);
  const SE3 T_world_kf0_placed = T_world_curr * T_kf0_curr.inverse();
  trajectory.addFrame(frameAt(1'333'000, T_world_kf0_placed * T_kf0_next, 0, T_kf0_next));

  const Trajectory corrected = trajectory.corrected(backend);
  ASSERT_EQ(corrected.size(), 3u);
  expectNear(backend.pose(0), T_world_kf0);
  expectNear(corrected[0].T_world_camera, T_world_kf0 * T_kf0_early);
  expectNear(corrected[1].T_world_camera, T_world_kf0 * T_kf0_curr);
  expectNear(corrected[2].T_world_camera, T_world_kf0 * T_kf0_next);
  // Odometry as reported.
  const Trajectory odometry = trajectory.odometry();
  expectNear(odometry[1].T_world_camera, T_world_curr);
}

}  // namespace
}  // namespace slamd
