// End to end on slamd's synthetic room (synth library), exact sensor, orb and fovis front ends.
// Issue 6's exact-mode target is every frame within 1 mm and 0.05 degrees: asserted on these 40
// frames, where orb reaches RMS 0.23 mm / 0.006 deg (max 0.68 mm / 0.016 deg) and fovis RMS
// 0.17 mm / 0.005 deg (max 0.43 mm / 0.012 deg); before the estimated noise scales, joint
// refinement and depth at the aligned patch both had RMS about 1.3 mm / 0.03 deg with peaks of
// 2-5 mm. The RMS bounds (0.5 mm, 0.015 deg) fail at that old level. Over the whole room
// sequence (901 frames, slamd-odometry-run) orb stays under 0.9 mm / 0.018 deg; fovis peaks at
// 1.9 mm / 0.043 deg.

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "slamd/synth/motion.hpp"
#include "slamd/synth/renderer.hpp"
#include "slamd/synth/scene.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "slamd/tracking/visual_odometry.hpp"

namespace slamd {
namespace {

struct Errors {
  double max_step_translation_m = 0.0;
  double max_step_rotation_deg = 0.0;
  double sum_sq_translation_m2 = 0.0;
  double sum_sq_rotation_deg2 = 0.0;
  int failures = 0;
  int frames = 0;
};

Errors runRoom(FrontEndType frontend, int frames) {
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/synthetic.yaml");
  config.set("synthetic.frames", std::to_string(frames));
  config.set("synthetic.sensor.exact", "true");
  auto source = createSyntheticSource("room", config);
  source->open();
  const Trajectory truth = *source->groundTruth();
  TrackingConfig tracking;
  tracking.frontend = frontend;
  VisualOdometry vo(tracking);
  Errors e;
  SE3 prev_true = SE3::Identity();
  while (true) {
    const FrameRead read = source->next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status != FrameRead::Status::kFrame) continue;
    const OdometryResult r = vo.processFrame(read.frame);
    const SE3 T_true = truth.at(static_cast<std::size_t>(e.frames)).T_world_camera;
    if (r.status != OdometryStatus::kOk) ++e.failures;
    if (e.frames > 0) {
      const SE3 step_true = prev_true.inverse() * T_true;
      const SE3 error = step_true.inverse() * r.T_prev_curr;
      e.max_step_translation_m = std::max(e.max_step_translation_m, error.translation().norm());
      if (std::getenv("SLAMD_TRACKING_DEBUG")) {
        std::fprintf(stderr, "%d kf=%d ref=%ld in=%d/%d rms=%.3f err=%.5f m %.4f deg step=%.4f m\n",
                     e.frames, r.is_keyframe, static_cast<long>(r.reference_keyframe_id),
                     r.stats.num_inliers, r.stats.num_matches, r.stats.reprojection_error_px,
                     error.translation().norm(), rotationAngleRad(error.linear()) * 180.0 / M_PI,
                     step_true.translation().norm());
      }
      const double rotation_deg = rotationAngleRad(error.linear()) * 180.0 / M_PI;
      e.max_step_rotation_deg = std::max(e.max_step_rotation_deg, rotation_deg);
      e.sum_sq_translation_m2 += error.translation().squaredNorm();
      e.sum_sq_rotation_deg2 += rotation_deg * rotation_deg;
    }
    prev_true = T_true;
    ++e.frames;
  }
  return e;
}

TEST(SyntheticRoom, OrbExactModeTracksEveryFrame) {
  cv::setNumThreads(1);
  const Errors e = runRoom(FrontEndType::kOrb, 40);
  EXPECT_EQ(e.frames, 40);
  EXPECT_EQ(e.failures, 0);
  EXPECT_LT(std::sqrt(e.sum_sq_translation_m2 / (e.frames - 1)), 0.0005);
  EXPECT_LT(std::sqrt(e.sum_sq_rotation_deg2 / (e.frames - 1)), 0.015);
  EXPECT_LT(e.max_step_translation_m, 0.001);
  EXPECT_LT(e.max_step_rotation_deg, 0.05);
}

TEST(SyntheticRoom, FovisExactModeTracksEveryFrame) {
  cv::setNumThreads(1);
  const Errors e = runRoom(FrontEndType::kFovis, 40);
  EXPECT_EQ(e.frames, 40);
  EXPECT_EQ(e.failures, 0);
  EXPECT_LT(std::sqrt(e.sum_sq_translation_m2 / (e.frames - 1)), 0.0005);
  EXPECT_LT(std::sqrt(e.sum_sq_rotation_deg2 / (e.frames - 1)), 0.015);
  EXPECT_LT(e.max_step_translation_m, 0.001);
  EXPECT_LT(e.max_step_rotation_deg, 0.05);
}

struct LaggingDepthErrors {
  double uncorrected_m = 0.0;
  double corrected_m = 0.0;
};

/// RMS position errors (metres) of odometry over the room, without and with
/// tracking.depth_time_correction, when each depth image is rendered colour_after_depth_s(k)
/// earlier than its colour image, as a Kinect v1 delivers them. Both see the same frames.
LaggingDepthErrors roomErrorsWithDepthTaken(double (*colour_after_depth_s)(int)) {
  constexpr int kFrames = 40;
  constexpr double kRateHz = 30.0;
  const synth::Scene scene = synth::makeRoom(synth::SceneParams(), 7);
  synth::MotionParams motion_params;
  motion_params.max_speed_mps = 0.5;
  const synth::CameraMotion motion(scene, synth::MotionKind::kRandom, motion_params, 7);
  const CameraIntrinsics K;
  const synth::Renderer renderer(scene, K);
  TrackingConfig uncorrected_config;
  uncorrected_config.depth_time_correction = false;
  VisualOdometry uncorrected(uncorrected_config);
  VisualOdometry corrected{TrackingConfig()};
  synth::RenderOutput colour, depth;
  double uncorrected_sum_m2 = 0.0, corrected_sum_m2 = 0.0;
  const SE3 T_world_first = motion.poseAt(1.0);
  for (int k = 0; k < kFrames; ++k) {
    const double t_s = 1.0 + k / kRateHz;
    const double depth_t_s = t_s - colour_after_depth_s(k);
    renderer.render(motion.poseAt(t_s), colour);
    renderer.render(motion.poseAt(depth_t_s), depth);
    auto frame = std::make_shared<RgbdFrame>();
    frame->utime = secondsToUtime(t_s);
    frame->depth_utime = secondsToUtime(depth_t_s);
    frame->sequence = k;
    frame->intrinsics = K;
    frame->color_bgr = colour.color_bgr.clone();
    frame->depth_m = depth.depth_m.clone();
    ensureGray(*frame);
    // Odometry starts at the identity: compare motions since the first frame.
    const Eigen::Vector3d t_first_true =
        (T_world_first.inverse() * motion.poseAt(t_s)).translation();
    const OdometryResult a = uncorrected.processFrame(frame);
    const OdometryResult b = corrected.processFrame(frame);
    EXPECT_EQ(a.status, OdometryStatus::kOk) << "frame " << k << ", uncorrected";
    EXPECT_EQ(b.status, OdometryStatus::kOk) << "frame " << k << ", corrected";
    uncorrected_sum_m2 += (t_first_true - a.T_world_camera.translation()).squaredNorm();
    corrected_sum_m2 += (t_first_true - b.T_world_camera.translation()).squaredNorm();
  }
  return {std::sqrt(uncorrected_sum_m2 / kFrames), std::sqrt(corrected_sum_m2 / kFrames)};
}

// Two unsynchronised 30 Hz streams: the lag wanders over +-15 ms.
double kinectLikeLag(int k) { return 0.003 * static_cast<double>((k * 7) % 11 - 5); }

TEST(SyntheticRoom, DepthTakenAtAnotherTimeThanColourIsMovedToTheColourTime) {
  cv::setNumThreads(1);
  // With depth rendered at the colour image's time the error is about 0.2 mm; lagging depth
  // gives about 6 mm, and the first keyframe's lag stays in (it has no motion to correct by).
  const LaggingDepthErrors e = roomErrorsWithDepthTaken(kinectLikeLag);
  std::printf("RMS position error with lagging depth: %.5f m uncorrected, %.5f m corrected\n",
              e.uncorrected_m, e.corrected_m);
  EXPECT_LT(e.corrected_m, 0.6 * e.uncorrected_m);
}

}  // namespace
}  // namespace slamd
