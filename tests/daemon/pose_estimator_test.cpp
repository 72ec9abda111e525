// PoseEstimator (the filter thread's step) through a tracking loss: the covariance a loss
// accumulates is dropped again when tracking relocalises against a keyframe from before it.

#include "slamd/app/pose_estimator.hpp"

#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>

#include <gtest/gtest.h>

#include "slamd/common/se3.hpp"

namespace slamd {
namespace {

/// A tracked frame without images: no vanishing points, so only its odometry moves the filter.
TrackedPacket imagelessFrame(Utime utime, TrackingState state, const SE3& T_prev_curr,
                             const Matrix6d& covariance) {
  auto frame = std::make_shared<RgbdFrame>();
  frame->utime = utime;
  TrackedPacket packet;
  packet.frame = frame;
  OdometryResult odometry;
  odometry.utime = utime;
  odometry.prev_utime = utime - 33'333;
  odometry.tracking_state = state;
  odometry.status =
      state == TrackingState::kLost ? OdometryStatus::kInsufficientFeatures : OdometryStatus::kOk;
  odometry.T_prev_curr = T_prev_curr;
  odometry.covariance = covariance;
  odometry.covariance_ref_curr = covariance;
  packet.odometry = odometry;
  return packet;
}

class PoseEstimatorThroughALoss : public ::testing::Test {
 protected:
  EstimatedPacket step(TrackingState state, const SE3& T_prev_curr, const Matrix6d& covariance) {
    TrackedPacket packet = imagelessFrame(utime_, state, T_prev_curr, covariance);
    utime_ += 33'333;
    return estimator_.process(std::move(packet));
  }

  static SE3 stepForward() {
    SE3 T = SE3::Identity();
    T.translation() = Eigen::Vector3d(0.01, 0.0, 0.0);
    return T;
  }

  PoseEstimator estimator_{FilterConfig(), VanishingPointSource::kPrecomputed};
  Utime utime_ = 1'000'000;
};

TEST_F(PoseEstimatorThroughALoss, ARelocalisedFrameIsAsCertainAsTheLastMeasuredOne) {
  const Matrix6d measured = Matrix6d::Identity() * 1e-6;
  EstimatedPacket out;
  for (int i = 0; i < 10; ++i) out = step(TrackingState::kOk, stepForward(), measured);
  const double variance_before_loss = out.pose.covariance.trace();
  const SE3 T_world_before_loss = out.pose.T_world_camera;

  // Lost: the pose is held, with tracking's "unknown" covariance (the filter caps each frame's
  // at what the motion limits allow).
  for (int i = 0; i < 5; ++i) {
    out = step(TrackingState::kLost, SE3::Identity(), Matrix6d::Identity() * 1e2);
  }
  const double variance_after_loss = out.pose.covariance.trace();
  EXPECT_GT(variance_after_loss, 10.0 * variance_before_loss);

  // Relocalised: the camera moved 6 cm during the loss, measured against a keyframe from before.
  SE3 jump = SE3::Identity();
  jump.translation() = Eigen::Vector3d(0.06, 0.0, 0.0);
  out = step(TrackingState::kRelocalized, jump, measured);
  EXPECT_EQ(out.pose.tracking_state, TrackingState::kRelocalized);
  EXPECT_LT(
      (out.pose.T_world_camera.translation() - (T_world_before_loss * jump).translation()).norm(),
      1e-9);
  // Nothing of the loss's covariance is left: the last measured frame's, the measurement's and
  // one frame's process noise.
  EXPECT_LT(out.pose.covariance.trace(), variance_before_loss + 1e-3);

  // Without relocalising (a new segment, held pose) the uncertainty stays as the loss left it.
  out = step(TrackingState::kLost, SE3::Identity(), Matrix6d::Identity() * 1e2);
  out = step(TrackingState::kOk, stepForward(), measured);
  EXPECT_GT(out.pose.covariance.trace(), 0.1 * variance_after_loss);
  std::printf("variance (trace): before the loss %.3g, after it %.3g\n", variance_before_loss,
              variance_after_loss);
}

}  // namespace
}  // namespace slamd

namespace slamd {
namespace {

// The corridor mode: tracking with few inliers (or not by features) switches it on, enough
// inliers for corridor_exit_frames frames in a row switch it off. (The fusion itself:
// FuseMotion.*; plane ICP: PlaneRegistration.*; the whole path: DaemonInProcess.InAPlainCorridor*.)
class PoseEstimatorCorridorMode : public ::testing::Test {
 protected:
  void step(int inliers, TrackingState state = TrackingState::kOk, bool dense = false) {
    TrackedPacket packet =
        imagelessFrame(utime_, state, SE3::Identity(), Matrix6d::Identity() * 1e-4);
    packet.odometry->stats.num_inliers = inliers;
    packet.odometry->stats.used_dense_alignment = dense;
    utime_ += 33'333;
    estimator_->process(std::move(packet));
  }

  static FilterConfig withCorridorMode() {
    FilterConfig config;
    config.planes.enabled = true;
    return config;
  }

  std::optional<PoseEstimator> estimator_{std::in_place, withCorridorMode(),
                                          VanishingPointSource::kPrecomputed};
  Utime utime_ = 1'000'000;
};

TEST_F(PoseEstimatorCorridorMode, FewInliersSwitchItOnAndEnoughForAWhileSwitchItOff) {
  const int exit_frames = FilterConfig().planes.corridor_exit_frames;
  step(300);
  EXPECT_FALSE(estimator_->corridorModeOn());
  step(20);
  EXPECT_TRUE(estimator_->corridorModeOn());
  for (int i = 0; i < exit_frames - 1; ++i) step(300);
  EXPECT_TRUE(estimator_->corridorModeOn());
  step(20);  // one scarce frame starts the count again
  for (int i = 0; i < exit_frames - 1; ++i) step(300);
  EXPECT_TRUE(estimator_->corridorModeOn());
  step(300);
  EXPECT_FALSE(estimator_->corridorModeOn());
  EXPECT_EQ(estimator_->corridorMode().switched_on.load(), 1u);
  EXPECT_EQ(estimator_->corridorMode().frames.load(), static_cast<std::uint64_t>(2 * exit_frames));
  // Frames features did not measure switch it on whatever their inlier count.
  step(300, TrackingState::kPredicted);
  EXPECT_TRUE(estimator_->corridorModeOn());
  for (int i = 0; i < exit_frames; ++i) step(300);
  step(300, TrackingState::kOk, /*dense=*/true);
  EXPECT_TRUE(estimator_->corridorModeOn());
  EXPECT_EQ(estimator_->corridorMode().switched_on.load(), 3u);
}

TEST_F(PoseEstimatorCorridorMode, DisabledItNeverSwitchesOn) {
  FilterConfig config;
  config.planes.enabled = false;
  estimator_.emplace(config, VanishingPointSource::kPrecomputed);
  for (int i = 0; i < 5; ++i) step(0, TrackingState::kLost);
  EXPECT_FALSE(estimator_->corridorModeOn());
  EXPECT_EQ(estimator_->corridorMode().switched_on.load(), 0u);
}

}  // namespace
}  // namespace slamd
