// The daemon with its back end on a synthetic lap of the room: the loop back to the start is
// found, the graph re-optimised, and the written trajectory (every frame at its keyframe's
// optimised pose) is more accurate than the same run without the back end.

#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "daemon_fixture.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/trajectory_error.hpp"

namespace slamd {
namespace {

struct RunResult {
  DaemonSummary summary;
  double ate_rmse_m = 0.0;
  /// Position error of the last frame, without any alignment: slamd's world is the first camera
  /// frame, so this is the drift accumulated over the lap, which closing the loop removes.
  double end_error_m = 0.0;
};

double endOfRunErrorM(const Trajectory& truth, const Trajectory& estimate) {
  const SE3 T_first_world = truth.front().T_world_camera.inverse();
  for (const StampedPose& pose : truth) {
    if (std::abs(pose.timestamp_s - estimate.back().timestamp_s) < 1e-4) {
      const Eigen::Vector3d truth_m = (T_first_world * pose.T_world_camera).translation();
      return (estimate.back().T_world_camera.translation() - truth_m).norm();
    }
  }
  ADD_FAILURE() << "the last estimated pose has no ground truth";
  return 0.0;
}

class DaemonWithBackEnd : public DaemonInProcess {
 protected:
  /// runRoomLap, once per process for each setting: the tests of this executable run in one
  /// process (ONE_PROCESS in CMakeLists.txt) and share the laps they run alike.
  const RunResult& roomLap(bool backend_enabled, const std::vector<std::string>& assignments = {}) {
    static std::map<std::pair<bool, std::vector<std::string>>, RunResult> laps;
    const auto key = std::make_pair(backend_enabled, assignments);
    auto found = laps.find(key);
    if (found == laps.end()) {
      const std::string tag = "lap" + std::to_string(laps.size());  // its trajectory file's name
      found = laps.emplace(key, runRoomLap(backend_enabled, tag, assignments)).first;
    }
    return found->second;
  }

  RunResult runRoomLap(bool backend_enabled, const std::string& tag,
                       const std::vector<std::string>& assignments) {
    Config config = smallSyntheticConfig(0);  // 0: one whole lap
    config.set("synthetic.trajectory", "loop");
    config.set("backend.enabled", backend_enabled ? "true" : "false");
    for (const std::string& assignment : assignments) config.applyOverride(assignment);
    DaemonOverrides overrides;
    overrides.source = "synthetic:room";
    overrides.trajectory_out = (dir_ / ("trajectory_" + tag + ".txt")).string();
    overrides.groundtruth_out = (dir_ / "groundtruth.txt").string();
    ShutdownSignals signals;
    SlamDaemon daemon(config, overrides);
    EXPECT_EQ(daemon.run(signals), kExitOk);
    RunResult result;
    result.summary = daemon.summary();
    // Every frame except the ones tracking lost (then there is no pose to write).
    const Trajectory estimate = readTumTrajectory(overrides.trajectory_out);
    EXPECT_LE(estimate.size(), result.summary.poses_published);
    EXPECT_GE(estimate.size(), result.summary.poses_published * 9 / 10);
    const Trajectory truth = readTumTrajectory(overrides.groundtruth_out);
    result.ate_rmse_m = eval::computeAte(truth, estimate).translation_m.rmse;
    result.end_error_m = endOfRunErrorM(truth, estimate);
    return result;
  }
};

TEST_F(DaemonWithBackEnd, ClosingTheLoopOfARoomLapReducesTrajectoryError) {
  const RunResult& odometry = roomLap(false);
  const RunResult& slam = roomLap(true);
  EXPECT_EQ(slam.summary.poses_published, odometry.summary.poses_published);
  EXPECT_EQ(slam.summary.errors, 0u);
  EXPECT_GE(slam.summary.loops, 1) << "the return to the start of the lap was not recognised";
  EXPECT_GE(slam.summary.optimizations, 1);
  EXPECT_EQ(slam.summary.relocalizations, 0) << "tracking was never lost on this lap";
  EXPECT_EQ(slam.summary.poses_not_localized, 0u) << "every pose is in the map's frame";
  EXPECT_LT(slam.end_error_m, 0.6 * odometry.end_error_m)
      << "drift at the end of the lap: " << slam.end_error_m << " m with the back end, "
      << odometry.end_error_m << " m without";
  // Odometry is already good over one lap of a textured room (ATE below 1 cm): the whole
  // trajectory must not get worse.
  EXPECT_LT(slam.ate_rmse_m, 1.05 * odometry.ate_rmse_m)
      << "ATE " << slam.ate_rmse_m << " m with the back end, " << odometry.ate_rmse_m
      << " m without";
  std::printf(
      "room lap: end drift %.4f m -> %.4f m, ATE %.4f m -> %.4f m; %llu frames re-used a map "
      "keyframe\n",
      odometry.end_error_m, slam.end_error_m, odometry.ate_rmse_m, slam.ate_rmse_m,
      static_cast<unsigned long long>(slam.summary.map_keyframe_reuses));
}

TEST_F(DaemonWithBackEnd, AfterTheLensIsCoveredTrackingResumesInTheSameMap) {
  // One second of black, depthless frames six seconds into the lap: tracking is lost, a new
  // segment starts, and the back end must put it back into the map by recognising a place.
  const std::vector<std::string> blackout = {"synthetic.blackout_start_s=6",
                                             "synthetic.blackout_duration_s=1"};
  const RunResult& slam = roomLap(true, blackout);
  EXPECT_GE(slam.summary.relocalizations, 1) << "the new tracking segment was never relocalised";
  // The camera moves about 0.8 m during the blackout: a segment left where tracking lost it
  // would be off by that much. Measured when written: 0.011 m.
  EXPECT_LT(slam.ate_rmse_m, 0.03);
  // Between the new segment's first pose and the correction that put it back, the poses were
  // published as not in the map's frame; none after.
  EXPECT_GE(slam.summary.poses_not_localized, 1u);
  EXPECT_FALSE(slam.summary.not_localized_at_end);
  std::printf(
      "room lap with a 1 s blackout: %lld relocalisations, ATE %.4f m; %llu poses published "
      "TRACKING_NOT_LOCALIZED before\n",
      static_cast<long long>(slam.summary.relocalizations), slam.ate_rmse_m,
      static_cast<unsigned long long>(slam.summary.poses_not_localized));
}

// daemon.memory_limit_mb far below what the run needs: the daemon degrades instead of failing.
// It keeps fewer keyframes, keeps new ones without their alignment images, makes the map far
// from the camera coarser, says so, and still tracks every frame.
TEST_F(DaemonWithBackEnd, AMemoryLimitBelowWhatTheRunNeedsMakesItKeepFewerKeyframes) {
  const RunResult& normal = roomLap(true);
  // A far map begins 1 m from the camera, so that the room has one.
  const RunResult& limited =
      roomLap(true, {"daemon.memory_limit_mb=1", "mapping.coarse_far_radius_m=1"});
  std::printf(
      "room lap: %lld keyframes of %lld bytes each without a limit, %lld of %lld bytes under a "
      "1 MB limit; ATE %.4f m / %.4f m; %lld map blocks merged far from the camera\n",
      static_cast<long long>(normal.summary.keyframes),
      static_cast<long long>(normal.summary.keyframes > 0
                                 ? normal.summary.keyframe_bytes / normal.summary.keyframes
                                 : 0),
      static_cast<long long>(limited.summary.keyframes),
      static_cast<long long>(limited.summary.keyframes > 0
                                 ? limited.summary.keyframe_bytes / limited.summary.keyframes
                                 : 0),
      normal.ate_rmse_m, limited.ate_rmse_m,
      static_cast<long long>(limited.summary.map_blocks_merged));
  EXPECT_EQ(normal.summary.memory_pressure_raised, 0u);
  EXPECT_EQ(normal.summary.map_blocks_merged, 0);
  EXPECT_GT(limited.summary.map_blocks_merged, 0);
  EXPECT_GE(limited.summary.memory_pressure_raised, 1u);
  EXPECT_GT(limited.summary.peak_resident_mb, 1.0);
  EXPECT_EQ(limited.summary.poses_published, normal.summary.poses_published);
  EXPECT_EQ(limited.summary.errors, 0u);
  EXPECT_LT(limited.summary.keyframes, normal.summary.keyframes);
  // New keyframes are kept without the image patch alignment uses (most of a keyframe's bytes).
  ASSERT_GT(limited.summary.keyframes, 0);
  EXPECT_LT(limited.summary.keyframe_bytes / limited.summary.keyframes,
            normal.summary.keyframe_bytes / normal.summary.keyframes / 2);
  EXPECT_LT(limited.ate_rmse_m, 0.05);
}

}  // namespace
}  // namespace slamd
