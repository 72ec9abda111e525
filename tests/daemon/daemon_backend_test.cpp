// The daemon with its back end on a synthetic lap of the room: the loop back to the start is
// found, the graph re-optimised, and the written trajectory (every frame at its keyframe's
// optimised pose) is more accurate than the same run without the back end.

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
};

class DaemonWithBackEnd : public DaemonInProcess {
 protected:
  RunResult runRoomLap(bool backend_enabled) {
    Config config = smallSyntheticConfig(0);  // 0: one whole lap
    config.set("synthetic.trajectory", "loop");
    config.set("backend.enabled", backend_enabled ? "true" : "false");
    const std::string tag = backend_enabled ? "on" : "off";
    DaemonOverrides overrides;
    overrides.source = "synthetic:room";
    overrides.trajectory_out = (dir_ / ("trajectory_" + tag + ".txt")).string();
    overrides.groundtruth_out = (dir_ / "groundtruth.txt").string();
    ShutdownSignals signals;
    SlamDaemon daemon(config, overrides);
    EXPECT_EQ(daemon.run(signals), kExitOk);
    RunResult result;
    result.summary = daemon.summary();
    const Trajectory estimate = readTumTrajectory(overrides.trajectory_out);
    EXPECT_EQ(estimate.size(), result.summary.poses_published);
    result.ate_rmse_m =
        eval::computeAte(readTumTrajectory(overrides.groundtruth_out), estimate).translation_m.rmse;
    return result;
  }
};

TEST_F(DaemonWithBackEnd, ClosingTheLoopOfARoomLapReducesTrajectoryError) {
  const RunResult odometry = runRoomLap(false);
  const RunResult slam = runRoomLap(true);
  EXPECT_EQ(slam.summary.poses_published, odometry.summary.poses_published);
  EXPECT_EQ(slam.summary.errors, 0u);
  EXPECT_GE(slam.summary.loops, 1) << "the return to the start of the lap was not recognised";
  EXPECT_GE(slam.summary.optimizations, 1);
  EXPECT_EQ(slam.summary.relocalizations, 0) << "tracking was never lost on this lap";
  // Measured when written: 0.0123 m without, 0.0080 m with the back end.
  EXPECT_LT(slam.ate_rmse_m, 0.8 * odometry.ate_rmse_m)
      << "ATE " << slam.ate_rmse_m << " m with the back end, " << odometry.ate_rmse_m
      << " m without";
}

}  // namespace
}  // namespace slamd
