// The daemon in-process, on a short synthetic sequence with in-process LCM (memq://): the stages'
// threads, queues and shutdown path, also run under ThreadSanitizer (`make tsan`).

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "daemon_fixture.hpp"
#include "slamd/app/slam_daemon.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/planes/plane_map.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

TEST_F(DaemonInProcess, ProcessesEveryFrameOfASequenceAndWritesOutputs) {
  Config config = smallSyntheticConfig(40);
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  overrides.trajectory_out = (dir_ / "trajectory.txt").string();
  overrides.groundtruth_out = (dir_ / "groundtruth.txt").string();
  overrides.map_out = (dir_ / "map.bt").string();
  ShutdownSignals signals;
  SlamDaemon daemon(config, overrides);
  ASSERT_EQ(daemon.run(signals), kExitOk);
  const DaemonSummary& summary = daemon.summary();
  // A dataset played as fast as possible waits for slow stages: nothing is dropped.
  EXPECT_EQ(summary.frames_captured, 40u);
  EXPECT_EQ(summary.frames_tracked, 40u);
  EXPECT_EQ(summary.poses_published, 40u);
  EXPECT_EQ(summary.frames_mapped, 40u);
  EXPECT_EQ(summary.drops, 0u);
  EXPECT_EQ(summary.errors, 0u);
  EXPECT_EQ(summary.poses_tracked + summary.poses_not_initialized, 40u);
  EXPECT_EQ(summary.poses_lost + summary.poses_predicted, 0u);
  EXPECT_FALSE(summary.tracking_lost_at_end);

  const Trajectory estimate = readTumTrajectory(overrides.trajectory_out);
  const Trajectory truth = readTumTrajectory(overrides.groundtruth_out);
  ASSERT_EQ(estimate.size(), 40u);
  ASSERT_GE(truth.size(), 40u);
  // The world frame is the first camera frame: compare motion relative to the first pose.
  const SE3 truth_first_inverse = truth.front().T_world_camera.inverse();
  double worst_m = 0.0;
  for (std::size_t i = 0; i < estimate.size(); ++i) {
    ASSERT_NEAR(estimate[i].timestamp_s, truth[i].timestamp_s, 1e-6);
    const Eigen::Vector3d truth_m = (truth_first_inverse * truth[i].T_world_camera).translation();
    worst_m = std::max(worst_m, (estimate[i].T_world_camera.translation() - truth_m).norm());
  }
  EXPECT_LT(worst_m, 0.02) << "tracking drifted";
  EXPECT_GT(std::filesystem::file_size(overrides.map_out), 100u);
}

TEST_F(DaemonInProcess, WritesTheMapsPlanesBesideTheMapAsPlyPolygons) {
  Config config = smallSyntheticConfig(40);
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  overrides.map_out = (dir_ / "map.bt").string();
  const DaemonSummary summary = runToEnd(config, overrides);
  EXPECT_EQ(summary.errors, 0u);
  std::vector<planes::PlyPolygon> polygons;
  std::string error;
  ASSERT_TRUE(planes::readPlaneMapPly((dir_ / "map.planes.ply").string(), polygons, &error))
      << error;
  // The room's first views: walls, floor and furniture.
  EXPECT_GE(polygons.size(), 3u);
  for (const planes::PlyPolygon& polygon : polygons) {
    EXPECT_GE(polygon.vertices.size(), 3u);
    EXPECT_NEAR(polygon.normal.norm(), 1.0, 1e-5);
  }

  // With the planes off, nothing is written beside the map.
  config.set("mapping.planes.enabled", "false");
  overrides.map_out = (dir_ / "without.bt").string();
  runToEnd(config, overrides);
  EXPECT_TRUE(std::filesystem::exists(overrides.map_out));
  EXPECT_FALSE(std::filesystem::exists(dir_ / "without.planes.ply"));
}

TEST_F(DaemonInProcess, ShutdownRequestDrainsQueuedFramesAndStillWritesOutputs) {
  Config config = smallSyntheticConfig(5000);
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  overrides.trajectory_out = (dir_ / "trajectory.txt").string();
  overrides.map_out = (dir_ / "map.bt").string();
  ShutdownSignals signals;
  SlamDaemon daemon(config, overrides);
  signals.request();  // as if SIGINT arrived the moment the pipeline started
  ASSERT_EQ(daemon.run(signals), kExitOk);
  const DaemonSummary& summary = daemon.summary();
  EXPECT_LT(summary.frames_captured, 5000u);
  // Whatever was captured was drained through every stage: nothing lost at shutdown.
  EXPECT_EQ(summary.frames_tracked, summary.frames_captured);
  EXPECT_EQ(summary.poses_published, summary.frames_captured);
  EXPECT_EQ(summary.drops, 0u);
  EXPECT_EQ(readTumTrajectory(overrides.trajectory_out).size(), summary.poses_published);
  EXPECT_TRUE(std::filesystem::exists(overrides.map_out));
}

TEST_F(DaemonInProcess, BackEndThreadRunsAlongsideTheOtherStages) {
  Config config = smallSyntheticConfig(60);
  config.set("backend.enabled", "true");  // loads the vocabulary the build wrote
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  overrides.trajectory_out = (dir_ / "trajectory.txt").string();
  overrides.map_out = (dir_ / "map.bt").string();
  const DaemonSummary summary = runToEnd(config, overrides);
  EXPECT_EQ(summary.poses_published, 60u);
  EXPECT_EQ(summary.drops, 0u);
  EXPECT_EQ(summary.errors, 0u);
  EXPECT_GE(summary.keyframes, 2);
  // The trajectory written at the end is the back end's: every tracked frame, at its keyframe's
  // optimised pose.
  EXPECT_EQ(readTumTrajectory(overrides.trajectory_out).size(), 60u);
  EXPECT_TRUE(std::filesystem::exists(overrides.map_out));
}

TEST_F(DaemonInProcess, InAPlainCorridorTheCorridorModeComesOnAndFusesPlaneOdometry) {
  // Walls with almost no texture (issue 23's plain corridor): tracking runs on few inliers, so
  // the corridor mode (on by default) switches on and the frames' plane measurements are fused.
  const auto plainCorridor = [this](bool corridor_mode) {
    Config config = smallSyntheticConfig(90);
    config.set("synthetic.texture_density", "0.04");
    config.set("synthetic.posters", "false");
    if (!corridor_mode) config.set("filter.planes.enabled", "false");
    DaemonOverrides overrides;
    overrides.source = "synthetic:corridor";
    return runToEnd(config, overrides);
  };
  const DaemonSummary summary = plainCorridor(true);
  EXPECT_EQ(summary.poses_published, 90u);
  EXPECT_EQ(summary.errors, 0u);
  EXPECT_GE(summary.corridor_mode_switched_on, 1u);
  EXPECT_GE(summary.corridor_mode_frames, 10u);
  EXPECT_GE(summary.plane_increments_fused, 5u);
  EXPECT_GT(summary.plane_increments_mean_nis, 0.0);
  // The corridor's vanishing points (or its walls' axes) correct the EKF, and the summary says so.
  EXPECT_GT(summary.direction_updates_accepted, 0);

  // Switched off, nothing of it runs.
  const DaemonSummary without = plainCorridor(false);
  EXPECT_EQ(without.poses_published, 90u);
  EXPECT_EQ(without.corridor_mode_switched_on, 0u);
  EXPECT_EQ(without.plane_increments_fused, 0u);
}

TEST_F(DaemonInProcess, SummarySaysPlainlyWhenTrackingIsLostAtTheEnd) {
  // The lens is covered from 1 s (frame 30) to the end: tracking has nothing to measure.
  Config config = smallSyntheticConfig(60);
  config.set("synthetic.blackout_start_s", "1.0");
  config.set("synthetic.blackout_duration_s", "100");
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  const DaemonSummary summary = runToEnd(config, overrides);
  EXPECT_EQ(summary.poses_published, 60u);
  EXPECT_LE(summary.poses_tracked, 30u);
  EXPECT_GE(summary.poses_tracked, 25u);
  EXPECT_GE(summary.poses_lost + summary.poses_predicted, 30u);
  EXPECT_TRUE(summary.tracking_lost_at_end);
  EXPECT_GE(summary.longest_loss_s, 0.9);
}

TEST_F(DaemonInProcess, ASequenceWithoutUsableDepthProducesNoMeasuredPoseAndSaysSo) {
  // Hostile-input issue, row 11: all-zero depth in every frame; the summary said "35 tracked,
  // 35 poses published" with an empty trajectory. Here the lens is covered from the first frame.
  Config config = smallSyntheticConfig(35);
  config.set("synthetic.blackout_start_s", "0");
  config.set("synthetic.blackout_duration_s", "100");
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  overrides.trajectory_out = (dir_ / "trajectory.txt").string();
  const DaemonSummary summary = runToEnd(config, overrides);
  EXPECT_EQ(summary.frames_captured, 35u);
  EXPECT_EQ(summary.poses_tracked, 0u);
  EXPECT_EQ(summary.poses_not_initialized + summary.poses_lost + summary.poses_predicted, 35u);
  EXPECT_TRUE(readTumTrajectory(overrides.trajectory_out).empty());
}

TEST_F(DaemonInProcess, RealTimeSourceBehindScheduleDropsFramesUnreadAndCountsThem) {
  // Played at 10x real time (300 Hz), the renderer cannot keep up: the source passes over the
  // frames it is too late for without rendering them, and every frame is accounted for.
  Config config = smallSyntheticConfig(150);
  config.set("capture.pacing.mode", "realtime");
  config.set("capture.pacing.speed", "10");
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  const DaemonSummary summary = runToEnd(config, overrides);
  EXPECT_EQ(summary.frames_captured + summary.frames_behind_schedule, 150u);
  EXPECT_GT(summary.frames_behind_schedule, 0u);
  EXPECT_EQ(summary.frames_tracked + summary.frames_dropped_before_tracking,
            summary.frames_captured);
  EXPECT_EQ(summary.poses_published, summary.frames_tracked);
  EXPECT_GT(summary.poses_tracked, 0u);
}

// Hostile-input issue, row 10: failed outputs exited 0, and one output could overwrite another.
TEST_F(DaemonInProcess, AnOutputThatCannotBeWrittenGivesTheOutputErrorExitCode) {
  for (const bool metrics : {false, true}) {
    Config config = smallSyntheticConfig(5);
    DaemonOverrides overrides;
    overrides.source = "synthetic:room";
    overrides.trajectory_out = metrics ? (dir_ / "trajectory.txt").string() : "/dev/full";
    if (metrics) overrides.metrics_out = (dir_ / "missing" / "metrics.json").string();
    ShutdownSignals signals;
    SlamDaemon daemon(config, overrides);
    EXPECT_EQ(daemon.run(signals), kExitOutputError) << (metrics ? "metrics" : "trajectory");
  }
}

TEST_F(DaemonInProcess, TwoOutputsNamingTheSameFileAreAConfigurationError) {
  Config config = smallSyntheticConfig(5);
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  overrides.trajectory_out = (dir_ / "out.bt").string();
  overrides.map_out = (dir_ / "." / "out.bt").string();
  try {
    SlamDaemon daemon(config, overrides);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("out.bt"), std::string::npos) << e.what();
  }
}

TEST_F(DaemonInProcess, AMissingVocabularyFileIsAConfigurationErrorNamingIt) {
  Config config = smallSyntheticConfig(5);
  config.set("backend.enabled", "true");
  const std::string missing = (dir_ / "missing.voc").string();
  config.set("backend.vocabulary_file", missing);
  DaemonOverrides overrides;
  overrides.source = "synthetic:room";
  try {
    SlamDaemon daemon(config, overrides);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }
}

TEST_F(DaemonInProcess, UnknownSourceIsAConfigurationTimeError) {
  Config config = smallSyntheticConfig(10);
  DaemonOverrides overrides;
  overrides.source = "webcam:0";
  EXPECT_ANY_THROW(SlamDaemon(config, overrides));
}

TEST_F(DaemonInProcess, MissingDatasetFolderIsASourceError) {
  Config config = smallSyntheticConfig(10);
  DaemonOverrides overrides;
  overrides.source = "tum:" + (dir_ / "no_such_folder").string();
  ShutdownSignals signals;
  try {
    SlamDaemon daemon(config, overrides);
    EXPECT_EQ(daemon.run(signals), kExitSourceError);
  } catch (const SourceError&) {
    SUCCEED() << "rejected while building the source";
  }
}

}  // namespace
}  // namespace slamd
