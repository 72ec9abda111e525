#include "slamd/tracking/visual_odometry.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "textured_box.hpp"

namespace slamd {
namespace {

double rotationErrorDeg(const SE3& a, const SE3& b) {
  return rotationAngleRad(a.linear().transpose() * b.linear()) * 180.0 / M_PI;
}

TEST(TrackingConfig, DefaultsAndValidation) {
  Config empty = Config::fromYamlString("tracking:\n  frontend: fovis\n");
  const TrackingConfig c = TrackingConfig::load(empty);
  EXPECT_EQ(c.frontend, FrontEndType::kFovis);
  EXPECT_EQ(c.max_features, TrackingConfig().max_features);
  Config bad = Config::fromYamlString("tracking:\n  frontend: surf\n");
  EXPECT_THROW(TrackingConfig::load(bad), ConfigError);
  Config range = Config::fromYamlString("tracking:\n  max_features: 5\n");
  EXPECT_THROW(TrackingConfig::load(range), ConfigError);
  Config depth = Config::fromYamlString("tracking:\n  min_depth_m: 3.0\n  max_depth_m: 2.0\n");
  EXPECT_THROW(TrackingConfig::load(depth), ConfigError);
  Config levels = Config::fromYamlString("tracking:\n  dense_levels: 3\n  dense_finest_level: 3\n");
  EXPECT_THROW(TrackingConfig::load(levels), ConfigError);
}

TEST(VisualOdometry, BadInputReturnsAStatusWithoutThrowing) {
  VisualOdometry vo;
  RgbdFrame empty;
  OdometryResult r;
  ASSERT_NO_THROW(r = vo.processFrame(empty));
  EXPECT_NE(r.status, OdometryStatus::kOk);
  EXPECT_NO_THROW(r = vo.processFrame(RgbdFramePtr()));
  EXPECT_NE(r.status, OdometryStatus::kOk);

  RgbdFrame wrong_type;
  wrong_type.intrinsics = test::fr1Camera();
  wrong_type.gray = cv::Mat(480, 640, CV_8UC1, cv::Scalar(128));
  wrong_type.depth_m = cv::Mat(480, 640, CV_16UC1, cv::Scalar(1000));
  r = vo.processFrame(wrong_type);
  EXPECT_EQ(r.status, OdometryStatus::kNoDepth);

  RgbdFrame wrong_size = wrong_type;
  wrong_size.depth_m = cv::Mat(10, 10, CV_32FC1, cv::Scalar(1.0f));
  EXPECT_EQ(vo.processFrame(wrong_size).status, OdometryStatus::kNoDepth);

  RgbdFrame image_wrong_size = wrong_type;
  image_wrong_size.gray = cv::Mat(100, 100, CV_8UC1, cv::Scalar(3));
  EXPECT_EQ(vo.processFrame(image_wrong_size).status, OdometryStatus::kInsufficientFeatures);

  // A textured image whose depth is all NaN or all zero: features but no depth.
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 1);
  RgbdFrame nan_depth = box.render(SE3::Identity(), test::fr1Camera());
  nan_depth.depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
  EXPECT_EQ(vo.processFrame(nan_depth).status, OdometryStatus::kNoDepth);
  nan_depth.depth_m.setTo(0.0f);
  EXPECT_EQ(vo.processFrame(nan_depth).status, OdometryStatus::kNoDepth);

  // Flat grey image with depth: no features.
  RgbdFrame flat = wrong_type;
  flat.depth_m = cv::Mat(480, 640, CV_32FC1, cv::Scalar(1.5f));
  EXPECT_EQ(vo.processFrame(flat).status, OdometryStatus::kInsufficientFeatures);
}

/// A short smooth trajectory inside the textured box (30 Hz, about 1 cm and 0.4 degrees a frame).
SE3 trajectoryPose(int i) {
  const double t = i / 30.0;
  Vector6d xi;
  xi << 0.3 * std::sin(1.1 * t), 0.1 * std::sin(0.7 * t), 0.25 * t, 0.1 * std::sin(0.9 * t),
      0.15 * std::sin(0.6 * t), 0.05 * t;
  return expSE3(xi);
}

struct SequenceErrors {
  double max_translation_m = 0.0;
  double max_rotation_deg = 0.0;
  double max_step_translation_m = 0.0;
  double max_step_rotation_deg = 0.0;
  int failures = 0;
  int keyframes = 0;
};

SequenceErrors runSynthetic(FrontEndType frontend, int frames) {
  TrackingConfig config;
  config.frontend = frontend;
  VisualOdometry vo(config);
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 42);
  SequenceErrors e;
  SE3 prev_true = SE3::Identity();
  SE3 prev_est = SE3::Identity();
  for (int i = 0; i < frames; ++i) {
    const SE3 T_true = trajectoryPose(i);
    RgbdFrame frame = box.render(T_true, test::fr1Camera());
    frame.utime = 1'000'000 + i * 33'333;
    frame.sequence = i;
    const OdometryResult r = vo.processFrame(frame);
    if (r.status != OdometryStatus::kOk) ++e.failures;
    if (r.is_keyframe) ++e.keyframes;
    // World = first camera = identity here, so errors are direct.
    e.max_translation_m = std::max(e.max_translation_m,
                                   (r.T_world_camera.translation() - T_true.translation()).norm());
    e.max_rotation_deg = std::max(e.max_rotation_deg, rotationErrorDeg(r.T_world_camera, T_true));
    if (i > 0) {
      const SE3 step_true = prev_true.inverse() * T_true;
      e.max_step_translation_m = std::max(
          e.max_step_translation_m, (r.T_prev_curr.translation() - step_true.translation()).norm());
      e.max_step_rotation_deg =
          std::max(e.max_step_rotation_deg, rotationErrorDeg(r.T_prev_curr, step_true));
      if (std::getenv("SLAMD_TRACKING_DEBUG")) {
        std::fprintf(stderr, "%d kf=%d ref=%ld in=%d/%d rms=%.3f step_err=%.5f m %.4f deg\n", i,
                     r.is_keyframe, static_cast<long>(r.reference_keyframe_id), r.stats.num_inliers,
                     r.stats.num_matches, r.stats.reprojection_error_px,
                     (r.T_prev_curr.translation() - step_true.translation()).norm(),
                     rotationErrorDeg(r.T_prev_curr, step_true));
      }
      EXPECT_TRUE(r.covariance.allFinite());
      EXPECT_GT(r.covariance.diagonal().minCoeff(), 0.0);
    }
    prev_true = T_true;
    prev_est = r.T_world_camera;
  }
  return e;
}

TEST(VisualOdometry, OrbTracksSyntheticTexturedRoomExactly) {
  const SequenceErrors e = runSynthetic(FrontEndType::kOrb, 30);
  EXPECT_EQ(e.failures, 0);
  EXPECT_GE(e.keyframes, 1);
  EXPECT_LT(e.max_step_translation_m, 0.001);
  EXPECT_LT(e.max_step_rotation_deg, 0.05);
  EXPECT_LT(e.max_translation_m, 0.005);
  EXPECT_LT(e.max_rotation_deg, 0.2);
}

TEST(VisualOdometry, FovisTracksSyntheticTexturedRoom) {
  const SequenceErrors e = runSynthetic(FrontEndType::kFovis, 30);
  EXPECT_EQ(e.failures, 0);
  EXPECT_LT(e.max_step_translation_m, 0.001);
  EXPECT_LT(e.max_step_rotation_deg, 0.05);
  EXPECT_LT(e.max_translation_m, 0.005);
}

TEST(VisualOdometry, PredictsThroughAShortGapThenDeclaresLostAndStartsANewSegment) {
  TrackingConfig config;
  config.max_predicted_frames = 2;
  config.dense_fallback = false;        // a frame without depth would be aligned photometrically
  config.relocalization_keyframes = 0;  // the camera returns to the same view: no relocalising
  VisualOdometry vo(config);
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 5);
  int i = 0;
  auto good = [&]() {
    RgbdFrame f = box.render(trajectoryPose(i), test::fr1Camera());
    f.utime = 1'000'000 + i * 33'333;
    ++i;
    return vo.processFrame(f);
  };
  auto blind = [&]() {
    RgbdFrame f = box.render(trajectoryPose(i), test::fr1Camera());
    f.utime = 1'000'000 + i * 33'333;
    f.depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
    ++i;
    return vo.processFrame(f);
  };
  EXPECT_EQ(good().segment, 0);
  good();
  good();
  OdometryResult r = blind();
  EXPECT_EQ(r.tracking_state, TrackingState::kPredicted);
  EXPECT_EQ(r.status, OdometryStatus::kNoDepth);
  r = good();  // recovers against the keyframe
  EXPECT_EQ(r.status, OdometryStatus::kOk);
  EXPECT_EQ(r.segment, 0);
  blind();
  blind();
  r = blind();
  EXPECT_EQ(r.tracking_state, TrackingState::kLost);
  r = good();
  EXPECT_EQ(r.status, OdometryStatus::kOk);
  EXPECT_TRUE(r.is_keyframe);
  EXPECT_EQ(r.segment, 1);
  ASSERT_TRUE(r.keyframe);
  EXPECT_EQ(r.keyframe->segment, 1);
}

TEST(VisualOdometry, AfterALossAFrameThatSeesARecentKeyframeAgainIsRelocalisedInTheSameSegment) {
  TrackingConfig config;
  config.max_predicted_frames = 2;
  config.dense_fallback = false;  // a frame without depth would be aligned photometrically
  VisualOdometry vo(config);
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 5);
  const test::TexturedBox other_box({-2, -1.5, -1}, {2, 1.5, 3}, 77);
  const SE3 T_world0_box = trajectoryPose(0).inverse();
  const auto render = [&](const test::TexturedBox& scene, int i, bool with_depth) {
    RgbdFrame f = scene.render(trajectoryPose(i), test::fr1Camera());
    f.utime = 1'000'000 + i * 33'333;
    if (!with_depth) f.depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
    return vo.processFrame(f);
  };
  const auto expectAt = [&](const OdometryResult& r, int i) {
    const SE3 truth = T_world0_box * trajectoryPose(i);
    EXPECT_LT((r.T_world_camera.translation() - truth.translation()).norm(), 0.005) << i;
    EXPECT_LT(rotationErrorDeg(r.T_world_camera, truth), 0.2) << i;
  };
  int i = 0;
  for (; i < 3; ++i) ASSERT_EQ(render(box, i, true).status, OdometryStatus::kOk);
  OdometryResult r;
  for (; i < 6; ++i) r = render(box, i, false);
  ASSERT_EQ(r.tracking_state, TrackingState::kLost);
  // The camera moved on during the loss (3 frames, about 3 cm): the pose held is that far off,
  // and the first frame with depth again is measured against the keyframe instead.
  r = render(box, i, true);
  EXPECT_EQ(r.status, OdometryStatus::kOk);
  EXPECT_EQ(r.tracking_state, TrackingState::kRelocalized);
  EXPECT_EQ(r.segment, 0);
  EXPECT_FALSE(r.is_keyframe);
  EXPECT_GE(r.stats.num_inliers, config.relocalization_min_inliers);
  expectAt(r, i);
  r = render(box, ++i, true);
  EXPECT_EQ(r.tracking_state, TrackingState::kOk);
  EXPECT_EQ(r.segment, 0);
  expectAt(r, i);

  // Lost again, and what comes back is a room none of the keyframes saw: a new segment there.
  for (int k = 0; k < 3; ++k) r = render(box, ++i, false);
  ASSERT_EQ(r.tracking_state, TrackingState::kLost);
  r = render(other_box, ++i, true);
  EXPECT_EQ(r.status, OdometryStatus::kOk);
  EXPECT_EQ(r.tracking_state, TrackingState::kOk);
  EXPECT_TRUE(r.is_keyframe);
  EXPECT_EQ(r.segment, 1);
}

// Few features (max_features 60 unless given), so every frame has fewer inliers against its
// keyframe than keyframe_min_inliers, in a turn of 2 degrees a frame: each such frame is refined
// jointly with its matches against the previous frame (and, with `dense`, aligned densely against
// it from the feature estimate), and stays as accurate as without.
struct FewInliersTurn {
  int refined_with_previous = 0;
  int refined_with_dense = 0;
  double max_rotation_error_deg = 0.0;
  double max_translation_error_m = 0.0;
};

FewInliersTurn runFewInliersTurn(bool previous_frame, bool dense = false, int max_features = 60) {
  TrackingConfig config;
  config.max_features = max_features;
  config.few_inliers_previous_frame = previous_frame;
  config.few_inliers_dense = dense;
  VisualOdometry vo(config);
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 7);
  FewInliersTurn out;
  for (int i = 0; i < 30; ++i) {
    SE3 T_true(Eigen::AngleAxisd(2.0 * i * M_PI / 180.0, Eigen::Vector3d::UnitY()));
    T_true.translation() = Eigen::Vector3d(0.005 * i, 0.0, 0.0);
    RgbdFrame frame = box.render(T_true, test::fr1Camera());
    frame.utime = 1'000'000 + i * 33'333;
    const OdometryResult r = vo.processFrame(frame);
    EXPECT_EQ(r.status, OdometryStatus::kOk) << i;
    if (r.stats.refined_with_previous_frame) ++out.refined_with_previous;
    if (r.stats.refined_with_dense_alignment) ++out.refined_with_dense;
    out.max_rotation_error_deg =
        std::max(out.max_rotation_error_deg, rotationErrorDeg(r.T_world_camera, T_true));
    out.max_translation_error_m =
        std::max(out.max_translation_error_m,
                 (r.T_world_camera.translation() - T_true.translation()).norm());
  }
  return out;
}

TEST(VisualOdometry, AFrameWithFewInliersIsRefinedWithThePreviousFrameToo) {
  const FewInliersTurn with = runFewInliersTurn(true);
  const FewInliersTurn without = runFewInliersTurn(false);
  std::printf(
      "few inliers, 2 deg a frame: %d frames refined with the previous one; worst error %.3f deg "
      "%.4f m (without: %.3f deg %.4f m)\n",
      with.refined_with_previous, with.max_rotation_error_deg, with.max_translation_error_m,
      without.max_rotation_error_deg, without.max_translation_error_m);
  EXPECT_GE(with.refined_with_previous, 10);
  EXPECT_EQ(without.refined_with_previous, 0);
  EXPECT_LT(with.max_rotation_error_deg, 0.3);
  EXPECT_LT(with.max_translation_error_m, 0.01);
}

TEST(VisualOdometry, AFrameWithFewInliersIsAlsoAlignedDenselyFromTheFeatureEstimate) {
  // 25 features: about half the frames of the turn have fewer inliers than keyframe_min_inliers.
  const FewInliersTurn with = runFewInliersTurn(true, true, 25);
  const FewInliersTurn without = runFewInliersTurn(true, false, 25);
  std::printf(
      "25 features, 2 deg a frame: %d frames aligned densely from the feature estimate; worst "
      "error %.3f deg %.4f m (features only: %.3f deg %.4f m)\n",
      with.refined_with_dense, with.max_rotation_error_deg, with.max_translation_error_m,
      without.max_rotation_error_deg, without.max_translation_error_m);
  EXPECT_GE(with.refined_with_dense, 8);
  EXPECT_EQ(without.refined_with_dense, 0);
  EXPECT_LT(with.max_rotation_error_deg, 0.03);
  EXPECT_LT(with.max_translation_error_m, 0.002);
  EXPECT_LT(with.max_rotation_error_deg, 0.5 * without.max_rotation_error_deg);
}

// The back end has not placed the segment in its map (after a loss, or a loaded session not yet
// localised) and says so with each set of map keyframes: frames whose view changed become
// keyframes sooner, at a wait that doubles with each one. step_m: the camera's motion along x per
// frame (0: it stands still); pending_until: the frame from which the back end says the segment
// is placed.
struct RelocalizationKeyframes {
  int keyframes = 0;
  int relocalization_keyframes = 0;
  /// Time since the keyframe before, for each keyframe made for relocalisation.
  std::vector<double> waits_s;
  int made_after_placed = 0;
};

RelocalizationKeyframes runAwaitingRelocalization(bool pending, double step_m,
                                                  int pending_until = 1000,
                                                  const TrackingConfig& config = TrackingConfig()) {
  VisualOdometry vo(config);
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 42);
  RelocalizationKeyframes out;
  Utime last_keyframe_utime = 0;
  std::int64_t last_keyframe_id = -1;
  for (int i = 0; i < 90; ++i) {
    if (i == pending_until) {
      // The back end placed the segment with the last keyframe it got, and says so at once.
      MapKeyframes placed;
      placed.anchor_id = last_keyframe_id;
      vo.setMapKeyframes(std::move(placed));
    }
    SE3 T_true = SE3::Identity();
    T_true.translation().x() = step_m * i;
    RgbdFrame frame = box.render(T_true, test::fr1Camera());
    frame.utime = 1'000'000 + i * 33'333;
    const OdometryResult r = vo.processFrame(frame);
    EXPECT_EQ(r.status, OdometryStatus::kOk) << i;
    EXPECT_LT(std::abs(r.T_world_camera.translation().x() - T_true.translation().x()), 0.005) << i;
    if (!r.is_keyframe) continue;
    ++out.keyframes;
    if (r.stats.relocalization_keyframe) {
      ++out.relocalization_keyframes;
      out.waits_s.push_back(static_cast<double>(r.utime - last_keyframe_utime) * 1e-6);
      if (i >= pending_until) ++out.made_after_placed;
    }
    last_keyframe_utime = r.utime;
    last_keyframe_id = r.keyframe->id;
    MapKeyframes map;
    map.anchor_id = r.keyframe->id;
    map.relocalization_pending = pending && i < pending_until;
    vo.setMapKeyframes(std::move(map));
  }
  return out;
}

TEST(VisualOdometry, WhileTheSegmentAwaitsRelocalisationAChangedViewBecomesAKeyframeSooner) {
  const RelocalizationKeyframes usual = runAwaitingRelocalization(false, 0.01);
  const RelocalizationKeyframes awaiting = runAwaitingRelocalization(true, 0.01);
  std::printf("3 s at 0.3 m/s: %d keyframes, %d awaiting relocalisation (%d made for it)\n",
              usual.keyframes, awaiting.keyframes, awaiting.relocalization_keyframes);
  ASSERT_EQ(TrackingConfig().relocalization_keyframe_interval_s, 0.25);
  EXPECT_EQ(usual.relocalization_keyframes, 0);
  ASSERT_GE(awaiting.relocalization_keyframes, 2);
  EXPECT_GT(awaiting.keyframes, usual.keyframes);
  // The k-th waited at least 0.25 s * 2^(k-1) since the keyframe before it.
  for (std::size_t k = 0; k < awaiting.waits_s.size(); ++k) {
    EXPECT_GE(awaiting.waits_s[k], std::ldexp(0.25, static_cast<int>(k)) - 1e-6) << k;
  }
  // The wait grows up to its bound, then stays.
  TrackingConfig bounded;
  bounded.relocalization_keyframe_max_interval_s = 0.5;
  const RelocalizationKeyframes steady = runAwaitingRelocalization(true, 0.01, 1000, bounded);
  EXPECT_GT(steady.relocalization_keyframes, awaiting.relocalization_keyframes);
  for (std::size_t k = 0; k < steady.waits_s.size(); ++k) {
    EXPECT_GE(steady.waits_s[k], std::min(std::ldexp(0.25, static_cast<int>(k)), 0.5) - 1e-6) << k;
  }
  // Once the back end says the segment is placed, only the usual keyframes.
  const RelocalizationKeyframes placed = runAwaitingRelocalization(true, 0.01, 20);
  EXPECT_EQ(placed.made_after_placed, 0);
  // A camera standing still offers the back end nothing new: no keyframes at all.
  const RelocalizationKeyframes still = runAwaitingRelocalization(true, 0.0);
  EXPECT_EQ(still.keyframes, 1);
}

// The camera goes 1.2 m along x and comes back. Tracking keeps only its last 2 keyframes, so on
// the way back the keyframes of the start have left its window; the map still has them (here:
// every keyframe made, at its true pose, as a back end that has optimised well holds them).
struct OutAndBack {
  int keyframes_on_the_way_back = 0;
  int map_keyframe_reuses = 0;
  double max_error_m = 0.0;
};

OutAndBack runOutAndBack(bool map_keyframes) {
  TrackingConfig config;
  config.keyframe_window = 2;
  config.map_keyframes = map_keyframes;
  VisualOdometry vo(config);
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 42);
  const int half = 60;
  const auto truth = [half](int i) {
    SE3 T = SE3::Identity();
    T.translation().x() = 0.02 * (i <= half ? i : 2 * half - i);
    return T;
  };
  std::vector<std::pair<KeyframePtr, SE3>> made;  // with its true pose
  OutAndBack out;
  for (int i = 0; i <= 2 * half; ++i) {
    const SE3 T_true = truth(i);
    RgbdFrame frame = box.render(T_true, test::fr1Camera());
    frame.utime = 1'000'000 + i * 33'333;
    frame.sequence = i;
    const OdometryResult r = vo.processFrame(frame);
    EXPECT_EQ(r.status, OdometryStatus::kOk) << i;
    out.max_error_m =
        std::max(out.max_error_m, (r.T_world_camera.translation() - T_true.translation()).norm());
    if (r.stats.used_map_keyframe) {
      ++out.map_keyframe_reuses;
      EXPECT_FALSE(r.is_keyframe);
      const bool known = std::any_of(made.begin(), made.end(), [&](const auto& m) {
        return m.first->id == r.reference_keyframe_id;
      });
      EXPECT_TRUE(known) << "frame " << i << " measured against keyframe "
                         << r.reference_keyframe_id;
    }
    if (!r.is_keyframe) continue;
    if (i > half) ++out.keyframes_on_the_way_back;
    MapKeyframes map;
    map.anchor_id = r.keyframe->id;
    for (const auto& [kf, T_world_kf] : made) {
      map.members.push_back({kf, T_true.inverse() * T_world_kf});
    }
    made.emplace_back(r.keyframe, T_true);
    vo.setMapKeyframes(std::move(map));
  }
  return out;
}

TEST(VisualOdometry, ComingBackWhereOnlyTheMapHoldsTheViewReusesTheMapsKeyframes) {
  const OutAndBack with_map = runOutAndBack(true);
  const OutAndBack without = runOutAndBack(false);
  std::printf(
      "out and back: %d keyframes on the way back with the map's (%d frames re-used one), "
      "%d without; max error %.4f / %.4f m\n",
      with_map.keyframes_on_the_way_back, with_map.map_keyframe_reuses,
      without.keyframes_on_the_way_back, with_map.max_error_m, without.max_error_m);
  ASSERT_GE(without.keyframes_on_the_way_back, 2) << "the window alone does not cover the way back";
  EXPECT_EQ(without.map_keyframe_reuses, 0) << "tracking.map_keyframes off ignores the map";
  EXPECT_GE(with_map.map_keyframe_reuses, 1);
  EXPECT_LT(with_map.keyframes_on_the_way_back, without.keyframes_on_the_way_back);
  EXPECT_LT(with_map.max_error_m, 0.005);
  EXPECT_LT(without.max_error_m, 0.005);
}

TEST(VisualOdometry, DenseAlignmentMeasuresFramesFeaturesCannot) {
  VisualOdometry vo;
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 5);
  const SE3 T_world0_box = trajectoryPose(0).inverse();
  const auto render = [&](int i) {
    RgbdFrame f = box.render(trajectoryPose(i), test::fr1Camera());
    f.utime = 1'000'000 + i * 33'333;
    return f;
  };
  const auto expectAt = [&](const OdometryResult& r, int i) {
    const SE3 truth = T_world0_box * trajectoryPose(i);
    EXPECT_LT((r.T_world_camera.translation() - truth.translation()).norm(), 0.005) << i;
    EXPECT_LT(rotationErrorDeg(r.T_world_camera, truth), 0.2) << i;
  };
  for (int i = 0; i < 3; ++i) ASSERT_EQ(vo.processFrame(render(i)).status, OdometryStatus::kOk);
  // An image without depth: photometric alignment against the last frame with depth.
  RgbdFrame no_depth = render(3);
  no_depth.depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
  OdometryResult r = vo.processFrame(no_depth);
  EXPECT_EQ(r.status, OdometryStatus::kOk);
  EXPECT_EQ(r.tracking_state, TrackingState::kOk);
  EXPECT_TRUE(r.stats.used_dense_alignment);
  expectAt(r, 3);
  // A blank image with depth: no features at all, but the box's walls are planes.
  RgbdFrame blank = render(4);
  blank.gray.setTo(128);
  blank.color_bgr.setTo(cv::Scalar(128, 128, 128));
  r = vo.processFrame(blank);
  EXPECT_EQ(r.status, OdometryStatus::kOk);
  EXPECT_TRUE(r.stats.used_dense_alignment);
  EXPECT_FALSE(r.is_keyframe);  // no features to track against later
  expectAt(r, 4);
  // Features again: tracked against the keyframe, still the first segment.
  r = vo.processFrame(render(5));
  EXPECT_EQ(r.status, OdometryStatus::kOk);
  EXPECT_FALSE(r.stats.used_dense_alignment);
  EXPECT_EQ(r.segment, 0);
  expectAt(r, 5);
  // Neither features nor depth nor image: nothing measures it.
  RgbdFrame nothing = render(6);
  nothing.gray.setTo(128);
  nothing.color_bgr.setTo(cv::Scalar(128, 128, 128));
  nothing.depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
  r = vo.processFrame(nothing);
  EXPECT_EQ(r.tracking_state, TrackingState::kPredicted);
  EXPECT_FALSE(r.stats.used_dense_alignment);
}

/// Tracks frames 0..9 of trajectoryPose(), then frame 10 with the camera moved by jump (in its
/// own frame), then frames 11 and 12 back on the trajectory.
std::vector<OdometryResult> trackWithAJump(const TrackingConfig& config, const SE3& jump) {
  VisualOdometry vo(config);
  const test::TexturedBox box({-2, -1.5, -1}, {2, 1.5, 3}, 42);
  std::vector<OdometryResult> results;
  for (int i = 0; i <= 12; ++i) {
    const SE3 T_world_camera = i == 10 ? trajectoryPose(i) * jump : trajectoryPose(i);
    RgbdFrame frame = box.render(T_world_camera, test::fr1Camera());
    frame.utime = 1'000'000 + i * 33'333;
    frame.sequence = i;
    results.push_back(vo.processFrame(frame));
  }
  return results;
}

/// A roll by 180 deg about the optical axis at frame 10: the view a repeating pattern can fake.
std::vector<OdometryResult> trackWithAFlip(const TrackingConfig& config) {
  SE3 roll = SE3::Identity();
  roll.linear() = expSO3(Eigen::Vector3d(0.0, 0.0, M_PI));
  return trackWithAJump(config, roll);
}

TEST(VisualOdometry, AFlipBeyondTheMotionLimitsIsVetoedAndPredicted) {
  // Without limits (100 rad/s allows any rotation in a frame period) and without the motion
  // prior's gate the flip is measured: the scene does fool the tracker, so the check below can
  // fail. (The gate alone rejects it too: 180 deg is 90 sigma of the default prior.)
  TrackingConfig unlimited;
  unlimited.motion_limits.max_angular_rate_radps = 100.0;
  unlimited.motion_limits.max_speed_mps = 100.0;
  unlimited.motion_prior_gate_sigma = 0.0;
  const std::vector<OdometryResult> fooled = trackWithAFlip(unlimited);
  ASSERT_EQ(fooled[10].status, OdometryStatus::kOk);
  EXPECT_GT(rotationAngleRad(fooled[10].T_prev_curr.linear()), 3.0);

  // With the default limits (4 rad/s, 3 m/s) the flip is vetoed, the frame predicted, and the
  // next frames measured again without a jump.
  const std::vector<OdometryResult> results = trackWithAFlip(TrackingConfig());
  for (int i = 0; i < 10; ++i) ASSERT_EQ(results[i].status, OdometryStatus::kOk) << i;
  const OdometryResult& flip = results[10];
  EXPECT_EQ(flip.status, OdometryStatus::kImplausibleMotion);
  EXPECT_EQ(flip.tracking_state, TrackingState::kPredicted);
  EXPECT_GE(flip.stats.implausible_estimates, 1);
  EXPECT_LT(rotationAngleRad(flip.T_prev_curr.linear()) * 180.0 / M_PI, 2.0);
  EXPECT_LT(rotationErrorDeg(flip.T_world_camera, trajectoryPose(10)), 1.0);
  for (int i = 11; i <= 12; ++i) {
    EXPECT_EQ(results[i].status, OdometryStatus::kOk) << i;
    EXPECT_LT(rotationErrorDeg(results[i].T_world_camera, trajectoryPose(i)), 0.2) << i;
    EXPECT_LT((results[i].T_world_camera.translation() - trajectoryPose(i).translation()).norm(),
              0.005)
        << i;
  }
  EXPECT_STREQ(odometryStatusName(OdometryStatus::kImplausibleMotion), "IMPLAUSIBLE_MOTION");
}

TEST(VisualOdometry, AnEstimateFarFromThePredictionIsRejectedAndPredicted) {
  // A 5 cm sideways jump within one frame period (1.5 m/s, within the 3 m/s limit) while the
  // camera moves at about 0.4 m/s: 2.5 sigma from the prediction with the default prior (0.6 m/s
  // of speed change), which accepts it; 15 sigma with a prior of 0.1 m/s, which rejects it.
  SE3 jump = SE3::Identity();
  jump.translation() = Eigen::Vector3d(0.05, 0.0, 0.0);
  const std::vector<OdometryResult> loose = trackWithAJump(TrackingConfig(), jump);
  ASSERT_EQ(loose[10].status, OdometryStatus::kOk);
  EXPECT_EQ(loose[10].stats.prior_disagreements, 0);
  EXPECT_LT(
      (loose[10].T_world_camera.translation() - (trajectoryPose(10) * jump).translation()).norm(),
      0.002);

  // Without dense alignment, a rejected frame is predicted.
  TrackingConfig tight;
  tight.motion_prior_sigma_mps = 0.1;
  tight.dense_fallback = false;
  tight.motion_prior_gate_sigma = 0.0;  // gate off: the jump is measured
  const std::vector<OdometryResult> ungated = trackWithAJump(tight, jump);
  ASSERT_EQ(ungated[10].status, OdometryStatus::kOk);
  EXPECT_FALSE(ungated[10].stats.used_dense_alignment);

  tight.motion_prior_gate_sigma = 6.0;
  const std::vector<OdometryResult> results = trackWithAJump(tight, jump);
  for (int i = 0; i < 10; ++i) {
    ASSERT_EQ(results[i].status, OdometryStatus::kOk) << i;
    EXPECT_EQ(results[i].stats.prior_disagreements, 0) << i;
  }
  const OdometryResult& rejected = results[10];
  EXPECT_EQ(rejected.status, OdometryStatus::kImplausibleMotion);
  EXPECT_EQ(rejected.tracking_state, TrackingState::kPredicted);
  EXPECT_GE(rejected.stats.prior_disagreements, 1);
  EXPECT_EQ(rejected.stats.implausible_estimates, 0);
  EXPECT_LT((rejected.T_world_camera.translation() - trajectoryPose(10).translation()).norm(),
            0.01);
  for (int i = 11; i <= 12; ++i) {
    EXPECT_EQ(results[i].status, OdometryStatus::kOk) << i;
    EXPECT_LT((results[i].T_world_camera.translation() - trajectoryPose(i).translation()).norm(),
              0.005)
        << i;
  }

  // With dense alignment (the default), the rejected frame is retried with it: the images,
  // weighed against the prior, measure the jump.
  tight.dense_fallback = true;
  const OdometryResult dense = trackWithAJump(tight, jump)[10];
  EXPECT_GE(dense.stats.prior_disagreements, 1);
  ASSERT_EQ(dense.status, OdometryStatus::kOk);
  EXPECT_TRUE(dense.stats.used_dense_alignment);
  EXPECT_LT((dense.T_world_camera.translation() - (trajectoryPose(10) * jump).translation()).norm(),
            0.005);
}

TEST(MotionLimits, ViolationsNameTheLimitAndNoiseWidensThem) {
  const MotionLimits limits;  // 3 m/s, 4 rad/s
  SE3 step = SE3::Identity();
  step.translation() = Eigen::Vector3d(0.05, 0.0, 0.0);
  EXPECT_EQ(limits.violation(step, 1.0 / 30), "");
  step.translation() = Eigen::Vector3d(0.2, 0.0, 0.0);  // 6 m/s
  EXPECT_NE(limits.violation(step, 1.0 / 30).find("translation"), std::string::npos);
  EXPECT_EQ(limits.violation(step, 1.0 / 30, 0.05), "");  // 3 sigma of 5 cm covers it
  EXPECT_EQ(limits.violation(step, 0.1), "");             // a dropped frame: more time
  SE3 turn = SE3::Identity();
  turn.linear() = expSO3(Eigen::Vector3d(0.0, 0.3, 0.0));  // 9 rad/s at 30 Hz
  EXPECT_NE(limits.violation(turn, 1.0 / 30).find("rotation"), std::string::npos);
  // A zero or negative interval is jitter: it counts as MotionLimits::kMinIntervalS.
  EXPECT_EQ(limits.violation(SE3::Identity(), 0.0), "");
  EXPECT_NE(limits.violation(step, -1.0), "");

  Config config = Config::fromYamlString("filter:\n  max_speed_mps: 1.5\n");
  EXPECT_DOUBLE_EQ(TrackingConfig::load(config).motion_limits.max_speed_mps, 1.5);
  Config bad = Config::fromYamlString("filter:\n  max_angular_rate_radps: 0\n");
  EXPECT_THROW(TrackingConfig::load(bad), ConfigError);
}

TEST(CompactKeyframe, KeepsFeaturesAndTheAlignmentImageOnlyAndCountsBytes) {
  auto frame = std::make_shared<RgbdFrame>();
  frame->color_bgr = cv::Mat(480, 640, CV_8UC3, cv::Scalar(1, 2, 3));
  frame->gray = cv::Mat(480, 640, CV_8UC1, cv::Scalar(7));
  frame->depth_m = cv::Mat(480, 640, CV_32FC1, cv::Scalar(1.5f));
  Keyframe keyframe;
  keyframe.id = 7;
  keyframe.frame = frame;
  FeatureSet& f = keyframe.features;
  for (int i = 0; i < 500; ++i) {
    f.keypoints.emplace_back(static_cast<float>(i), 10.0f, 7.0f);
    f.pixels.emplace_back(static_cast<double>(i), 10.0);
    f.points.emplace_back(0.0, 0.0, 1.5);
    f.scale.push_back(1.0f);
  }
  f.descriptors = cv::Mat(500, 32, CV_8UC1, cv::Scalar(0));
  f.gray = frame->gray;  // shared with the frame: counted once
  cv::GaussianBlur(frame->gray, f.align_gray, cv::Size(5, 5), 1.0);
  const std::size_t feature_bytes = 500 * (sizeof(cv::KeyPoint) + sizeof(Eigen::Vector2d) +
                                           sizeof(Eigen::Vector3d) + sizeof(float)) +
                                    500 * 32;
  const std::size_t image_bytes = 640 * 480 * (3 + 1 + 4) + 640 * 480;  // frame + align_gray
  EXPECT_EQ(keyframeBytes(keyframe), feature_bytes + image_bytes);

  const auto compact = compactKeyframe(keyframe, true);
  EXPECT_EQ(compact->id, 7);
  EXPECT_EQ(compact->frame, nullptr);
  EXPECT_TRUE(compact->features.gray.empty());
  EXPECT_EQ(compact->features.align_gray.data, f.align_gray.data) << "shared, not copied";
  EXPECT_EQ(compact->features.size(), 500u);
  EXPECT_EQ(keyframeBytes(*compact), feature_bytes + 640 * 480);
  EXPECT_EQ(keyframeBytes(*compactKeyframe(keyframe, false)), feature_bytes);
  EXPECT_NE(keyframe.frame, nullptr) << "the original keeps its images";
}

}  // namespace
}  // namespace slamd
