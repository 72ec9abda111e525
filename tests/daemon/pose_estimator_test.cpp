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

#include "plain_corridor.hpp"
#include "slamd/planes/plane_segmenter.hpp"

namespace slamd {
namespace {

// The corridor mode's fusion: each frame's planes are registered against the planes of the
// frame tracking measured it from (or the first segmented frame measured from it), so a plane
// error is the reference's and does not add up frame by frame.
class PoseEstimatorPlaneFusion : public ::testing::Test {
 protected:
  static constexpr Utime kFirstUtime = 1'000'000;
  static constexpr Utime kFrameUs = 33'333;
  static constexpr int kFrames = 12;

  /// Tracking's T_ref_curr for frame k (k = 0 is the keyframe): the true motion along the
  /// corridor (z), 2 cm a frame, off across it (x, y) by errors that change sign from frame to
  /// frame, and along it by a constant 5 mm.
  static SE3 trackedFromKeyframe(int k) {
    SE3 T = SE3::Identity();
    if (k == 0) return T;
    const double sign = (k % 2 == 0) ? 1.0 : -1.0;
    T.translation() = Eigen::Vector3d(0.015 * sign, -0.01 * sign, 0.02 * k + 0.005);
    return T;
  }
  static SE3 trueFromKeyframe(int k) { return SE3(Eigen::Translation3d(0.0, 0.0, 0.02 * k)); }

  /// Frame k as tracking measured it against frame 0, its planes when `segmented`.
  TrackedPacket frame(int k, bool segmented) {
    const SE3 T_world_true = trueFromKeyframe(k);
    auto frame = std::make_shared<RgbdFrame>(test::renderCorridor(T_world_true));
    frame->utime = kFirstUtime + k * kFrameUs;
    TrackedPacket packet;
    OdometryResult odometry;
    odometry.utime = frame->utime;
    odometry.prev_utime = frame->utime - kFrameUs;
    odometry.tracking_state = TrackingState::kOk;
    odometry.status = OdometryStatus::kOk;
    odometry.is_keyframe = k == 0;
    odometry.ref_utime = k == 0 ? 0 : kFirstUtime;
    odometry.T_ref_curr = trackedFromKeyframe(k);
    odometry.T_prev_curr =
        k == 0 ? SE3::Identity() : trackedFromKeyframe(k - 1).inverse() * trackedFromKeyframe(k);
    // 2 cm a direction (the errors above are within it), rotation well known.
    Matrix6d covariance = Matrix6d::Identity() * 4e-4;
    covariance.bottomRightCorner<3, 3>() = Eigen::Matrix3d::Identity() * 1e-8;
    odometry.covariance = covariance;
    odometry.covariance_ref_curr = covariance;
    odometry.stats.num_inliers = 20;  // features have run out: the mode comes on
    if (segmented) {
      PlaneSegmentationPacket planes;
      planes.utime = frame->utime;
      planes.planes = std::make_shared<planes::PlaneSegmentation>(segmenter_.segment(*frame));
      packet.plane_segmentation = planes;
    }
    packet.frame = std::move(frame);
    packet.odometry = odometry;
    return packet;
  }

  static FilterConfig withCorridorMode() {
    FilterConfig config;
    config.planes.enabled = true;
    return config;
  }

  planes::PlaneSegmenter segmenter_;
  PoseEstimator estimator_{withCorridorMode(), VanishingPointSource::kPrecomputed};
};

TEST_F(PoseEstimatorPlaneFusion, PlanesCorrectWhatTheyMeasureAgainstTheKeyframe) {
  for (int k = 0; k < kFrames; ++k) {
    SCOPED_TRACE("frame " + std::to_string(k));
    const EstimatedPacket out = estimator_.process(frame(k, /*segmented=*/true));
    const Eigen::Vector3d error =
        out.pose.T_world_camera.translation() - trueFromKeyframe(k).translation();
    // Across the corridor the planes hold every frame to the keyframe: tracking was 1-1.5 cm
    // off there. Along it (z) they measure nothing: tracking's value stays.
    EXPECT_LT(error.head<2>().norm(), 0.002);
    EXPECT_NEAR(error.z(), k == 0 ? 0.0 : 0.005, 0.002);
  }
  EXPECT_EQ(estimator_.corridorMode().fused.load(), static_cast<std::uint64_t>(kFrames - 1));
  EXPECT_EQ(estimator_.corridorMode().gated.load(), 0u);
}

TEST_F(PoseEstimatorPlaneFusion, AFrameWithoutPlanesKeepsTheCorrectionAndTheNextOneIsFusedAgain) {
  constexpr int kUnsegmented = 6;
  EstimatedPacket previous;
  for (int k = 0; k < kFrames; ++k) {
    SCOPED_TRACE("frame " + std::to_string(k));
    TrackedPacket packet = frame(k, /*segmented=*/k != kUnsegmented);
    const SE3 tracked_increment = packet.odometry->T_prev_curr;
    const EstimatedPacket out = estimator_.process(std::move(packet));
    const Eigen::Vector3d error =
        out.pose.T_world_camera.translation() - trueFromKeyframe(k).translation();
    if (k == kUnsegmented) {
      // Tracking's increment from the previous (fused) pose: no jump back to tracking's pose
      // relative to the keyframe, which would undo the previous frame's correction at once.
      const SE3 step = previous.pose.T_world_camera.inverse() * out.pose.T_world_camera;
      EXPECT_LT((step.translation() - tracked_increment.translation()).norm(), 1e-6);
    } else {
      EXPECT_LT(error.head<2>().norm(), 0.002);
    }
    previous = out;
  }
  EXPECT_EQ(estimator_.corridorMode().fused.load(), static_cast<std::uint64_t>(kFrames - 2));
}

TEST_F(PoseEstimatorPlaneFusion, WithoutTheKeyframesPlanesTheFirstSegmentedFrameIsTheAnchor) {
  // The mode came on after the keyframe: frames 0-2 are not segmented, frame 3 is the first.
  constexpr int kAnchor = 3;
  const Eigen::Vector3d anchor_error =
      trackedFromKeyframe(kAnchor).translation() - trueFromKeyframe(kAnchor).translation();
  for (int k = 0; k < kFrames; ++k) {
    SCOPED_TRACE("frame " + std::to_string(k));
    const EstimatedPacket out = estimator_.process(frame(k, /*segmented=*/k >= kAnchor));
    const Eigen::Vector3d error =
        out.pose.T_world_camera.translation() - trueFromKeyframe(k).translation();
    if (k < kAnchor) continue;
    // Every later frame is registered against the anchor, whose position relative to the
    // keyframe is tracking's: across the corridor each carries the anchor's error, not a sum.
    EXPECT_LT((error.head<2>() - anchor_error.head<2>()).norm(), 0.002);
    EXPECT_NEAR(error.z(), 0.005, 0.002);
  }
  EXPECT_EQ(estimator_.corridorMode().fused.load(),
            static_cast<std::uint64_t>(kFrames - kAnchor - 1));
  // Only the anchor itself had nothing to be registered against.
  EXPECT_EQ(estimator_.corridorMode().unmatched.load(), 1u);
}

}  // namespace
}  // namespace slamd
