// TUM fr1/xyz: the first 150 frames with each fast front end, and the whole sequence with orb
// against issue 6's targets (ATE <= 0.025 m, RPE(1 s) <= 0.020 m). Measured (release build):
// 150 frames ATE orb 0.012 m, fovis 0.014 m (before the joint refinement and noise scales:
// 0.026 and 0.018); whole sequence orb ATE 0.0135 m, RPE 0.0163 m (before: 0.032 and 0.025).

#include <map>
#include <tuple>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "sanitizer_runs.hpp"
#include "slamd/capture/tum_source.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/tracking/visual_odometry.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

struct RunResult {
  double ate_rmse_m = 0.0;
  double rpe_rmse_m = 0.0;  ///< translation, 1 s
  int frames = 0;
  int failures = 0;
  int frames_with_local_map_inliers = 0;
};

/// Runs the front end over the first max_frames frames (0 = all).
RunResult runFrames(FrontEndType frontend, int max_frames, bool local_map = true) {
  const auto folder = test::findDataset("tum_fr1_xyz");
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/tum_fr1.yaml");
  TrackingConfig tracking = TrackingConfig::load(config);
  tracking.frontend = frontend;
  tracking.local_map = local_map;
  TumSource source(folder->string(), TumSourceConfig::load(config));
  source.open();
  VisualOdometry vo(tracking);
  Trajectory estimate;
  RunResult result;
  while (max_frames <= 0 || result.frames < max_frames) {
    const FrameRead read = source.next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status != FrameRead::Status::kFrame) continue;
    const OdometryResult r = vo.processFrame(read.frame);
    ++result.frames;
    if (r.status != OdometryStatus::kOk) ++result.failures;
    if (r.stats.local_map_inliers > 0) ++result.frames_with_local_map_inliers;
    estimate.push_back({utimeToSeconds(r.utime), r.T_world_camera});
  }
  result.ate_rmse_m = eval::computeAte(*source.groundTruth(), estimate).translation_m.rmse;
  result.rpe_rmse_m = eval::computeRpe(*source.groundTruth(), estimate).translation_m.rmse;
  return result;
}

/// runFrames, once per process for each argument set: the tests of this executable run in one
/// process (ONE_PROCESS in CMakeLists.txt) and share the runs over the whole sequence.
const RunResult& runFirstFrames(FrontEndType frontend, int max_frames, bool local_map = true) {
  static std::map<std::tuple<FrontEndType, int, bool>, RunResult> runs;
  const auto key = std::make_tuple(frontend, max_frames, local_map);
  auto found = runs.find(key);
  if (found == runs.end()) {
    found = runs.emplace(key, runFrames(frontend, max_frames, local_map)).first;
  }
  return found->second;
}

TEST(TumFr1Xyz, OrbTracksTheFirst150Frames) {
  if (!test::findDataset("tum_fr1_xyz")) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  const RunResult& r = runFirstFrames(FrontEndType::kOrb, 150);
  EXPECT_EQ(r.frames, 150);
  EXPECT_EQ(r.failures, 0);
  EXPECT_LT(r.ate_rmse_m, 0.018);
  RecordProperty("ate_rmse_m", std::to_string(r.ate_rmse_m));
}

TEST(TumFr1Xyz, FovisTracksTheFirst150Frames) {
  if (!test::findDataset("tum_fr1_xyz")) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  const RunResult& r = runFirstFrames(FrontEndType::kFovis, 150);
  EXPECT_EQ(r.frames, 150);
  EXPECT_EQ(r.failures, 0);
  EXPECT_LT(r.ate_rmse_m, 0.018);
  RecordProperty("ate_rmse_m", std::to_string(r.ate_rmse_m));
}

TEST(TumFr1Xyz, OrbMeetsTheAccuracyTargetsOnTheWholeSequence) {
  if (!test::findDataset("tum_fr1_xyz")) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  const RunResult& r = runFirstFrames(FrontEndType::kOrb, test::accuracyRunFrames(150));
  EXPECT_EQ(r.failures, 0);
  SLAMD_SKIP_ACCURACY_CHECKS_UNDER_SANITIZER();
  EXPECT_GT(r.frames, 790);
  EXPECT_LT(r.ate_rmse_m, 0.02);
  EXPECT_LT(r.rpe_rmse_m, 0.02);
  RecordProperty("ate_rmse_m", std::to_string(r.ate_rmse_m));
  RecordProperty("rpe_rmse_m", std::to_string(r.rpe_rmse_m));
}

TEST(TumFr1Xyz, TrackingAgainstTheLocalMapLowersTheError) {
  // Measured: ATE 0.0108 m with the local map, 0.0131 m against the keyframe and the two most
  // recent others (joint_references); RPE(1 s) 0.0153 and 0.0163 m.
  if (!test::findDataset("tum_fr1_xyz")) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  const int frames = test::accuracyRunFrames(150);
  const RunResult& with_map = runFirstFrames(FrontEndType::kOrb, frames, true);
  const RunResult& without = runFirstFrames(FrontEndType::kOrb, frames, false);
  EXPECT_EQ(with_map.failures, 0);
  EXPECT_GT(with_map.frames_with_local_map_inliers, with_map.frames / 2);
  EXPECT_EQ(without.frames_with_local_map_inliers, 0);
  SLAMD_SKIP_ACCURACY_CHECKS_UNDER_SANITIZER();
  EXPECT_LT(with_map.ate_rmse_m, 0.012);
  EXPECT_LT(with_map.ate_rmse_m, without.ate_rmse_m);
  EXPECT_LT(with_map.rpe_rmse_m, without.rpe_rmse_m);
  RecordProperty("ate_rmse_m", std::to_string(with_map.ate_rmse_m));
  RecordProperty("ate_rmse_m_without_local_map", std::to_string(without.ate_rmse_m));
}

}  // namespace
}  // namespace slamd
