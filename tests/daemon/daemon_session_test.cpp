// Sessions end to end: a run saves its map, keyframes and pose graph (--session-out); a later run
// loads them (--session-in) and localises in that map, so its poses come out in the first run's
// frame. Bad sessions are refused before anything starts.

#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "daemon_fixture.hpp"
#include "slamd/backend/session.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/mapping/keyframe_cloud_io.hpp"
#include "slamd/mapping/mapping_config.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

class DaemonSessions : public DaemonInProcess {
 protected:
  /// fr1/xyz frames [first, first + count) with the back end on; returns the summary.
  DaemonSummary runFr1Part(const std::string& folder, int first, int count,
                           const DaemonOverrides& outputs,
                           const std::vector<std::string>& assignments = {}) {
    Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/tum_fr1.yaml");
    config.set("lcm.url", "memq://");
    config.set("backend.enabled", "true");
    config.set("capture.tum.first_frame", std::to_string(first));
    config.set("capture.tum.frame_count", std::to_string(count));
    for (const std::string& assignment : assignments) config.applyOverride(assignment);
    DaemonOverrides overrides = outputs;
    overrides.source = "tum:" + folder;
    return runToEnd(config, overrides);
  }
};

// The test: map the first half of fr1/xyz and save; a new process on the second half in
// backend.mode=localize puts every pose in the first session's frame. Checked by evaluating both
// halves together under one alignment to the ground truth: a second half in a frame of its own
// (its first camera pose) would be off by the camera's motion over the first half.
TEST_F(DaemonSessions, TheSecondHalfOfFr1IsLocalisedInTheMapOfTheFirst) {
  const auto folder = test::findDataset("tum_fr1_xyz");
  if (!folder) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  const std::string session = (dir_ / "session").string();
  DaemonOverrides first_outputs;
  first_outputs.trajectory_out = (dir_ / "first.txt").string();
  first_outputs.session_out = session;
  const DaemonSummary first = runFr1Part(folder->string(), 0, 400, first_outputs);
  ASSERT_GT(first.keyframes, 0);
  const SessionInfo info = readSessionInfo(session);
  EXPECT_EQ(info.keyframes, first.keyframes);
  EXPECT_GT(info.map_voxels, 0);

  DaemonOverrides second_outputs;
  second_outputs.trajectory_out = (dir_ / "second.txt").string();
  second_outputs.session_in = session;
  const DaemonSummary second =
      runFr1Part(folder->string(), 400, 0, second_outputs, {"backend.mode=localize"});
  EXPECT_EQ(second.errors, 0u);
  EXPECT_GE(second.relocalizations, 1) << "the run never localised in the loaded map";
  EXPECT_GE(second.frames_before_localization, 0) << "never localised in the loaded map";
  EXPECT_LE(second.frames_before_localization, 10)
      << "the first frame localised in the loaded map came after frame 10";

  const Trajectory truth = readTumTrajectory((*folder / "groundtruth.txt").string());
  const Trajectory first_half = readTumTrajectory(first_outputs.trajectory_out);
  const Trajectory second_half = readTumTrajectory(second_outputs.trajectory_out);
  EXPECT_GE(second_half.size(), second.poses_published - second.poses_lost);
  Trajectory both = first_half;
  both.insert(both.end(), second_half.begin(), second_half.end());
  const double first_ate_m = eval::computeAte(truth, first_half).translation_m.rmse;
  const double second_ate_m = eval::computeAte(truth, second_half).translation_m.rmse;
  const double both_ate_m = eval::computeAte(truth, both).translation_m.rmse;
  std::printf(
      "fr1/xyz halves: first %.4f m (%lld keyframes), second localised %.4f m, both in one "
      "frame %.4f m; localised at frame %lld (%llu poses published before)\n",
      first_ate_m, static_cast<long long>(first.keyframes), second_ate_m, both_ate_m,
      static_cast<long long>(second.frames_before_localization),
      static_cast<unsigned long long>(second.poses_not_localized));
  EXPECT_LT(second_ate_m, 0.015);
  EXPECT_LT(both_ate_m, 0.015);
}

// The synthetic test: map a lap of the room and save; a new process that starts at
// another place in the room (another motion, starting elsewhere) is relocalised within 1 s of
// frames and its poses are in the first run's frame: the two runs together, under one alignment
// to the room's ground truth, are as accurate as each alone.
TEST_F(DaemonSessions, AStartElsewhereInTheMappedRoomIsLocalisedWithinASecond) {
  const std::string session = (dir_ / "room").string();
  Config lap = smallSyntheticConfig(0);
  lap.set("synthetic.trajectory", "loop");
  lap.set("backend.enabled", "true");
  DaemonOverrides lap_outputs;
  lap_outputs.source = "synthetic:room";
  lap_outputs.trajectory_out = (dir_ / "lap.txt").string();
  lap_outputs.groundtruth_out = (dir_ / "lap_truth.txt").string();
  lap_outputs.session_out = session;
  const DaemonSummary mapped = runToEnd(lap, lap_outputs);
  ASSERT_GT(mapped.keyframes, 0);

  // Another motion through the same room (same seed: same room), 4 s of it, with timestamps of
  // its own so that the two runs can be evaluated together.
  Config elsewhere = smallSyntheticConfig(120);
  elsewhere.set("synthetic.trajectory", "random");
  elsewhere.set("synthetic.start_time_s", "1600001000");
  elsewhere.set("backend.enabled", "true");
  elsewhere.set("backend.mode", "localize");
  DaemonOverrides outputs;
  outputs.source = "synthetic:room";
  outputs.trajectory_out = (dir_ / "elsewhere.txt").string();
  outputs.groundtruth_out = (dir_ / "elsewhere_truth.txt").string();
  outputs.session_in = session;
  const DaemonSummary localised = runToEnd(elsewhere, outputs);
  EXPECT_EQ(localised.errors, 0u);
  ASSERT_GE(localised.frames_before_localization, 0) << "never localised in the room's map";
  EXPECT_LE(localised.frames_before_localization, 30) << "not localised within 1 s of frames";

  Trajectory truth = readTumTrajectory(lap_outputs.groundtruth_out);
  const Trajectory elsewhere_truth = readTumTrajectory(outputs.groundtruth_out);
  truth.insert(truth.end(), elsewhere_truth.begin(), elsewhere_truth.end());
  Trajectory both = readTumTrajectory(lap_outputs.trajectory_out);
  const Trajectory second = readTumTrajectory(outputs.trajectory_out);
  both.insert(both.end(), second.begin(), second.end());
  const double lap_ate_m =
      eval::computeAte(truth, readTumTrajectory(lap_outputs.trajectory_out)).translation_m.rmse;
  const double second_ate_m = eval::computeAte(truth, second).translation_m.rmse;
  const double both_ate_m = eval::computeAte(truth, both).translation_m.rmse;
  std::printf(
      "room: lap %.4f m (%lld keyframes); elsewhere localised at frame %lld, %.4f m alone, "
      "%.4f m with the lap in one frame\n",
      lap_ate_m, static_cast<long long>(mapped.keyframes),
      static_cast<long long>(localised.frames_before_localization), second_ate_m, both_ate_m);
  EXPECT_LT(both_ate_m, 0.03);
}

// backend.mode=slam (multi-session): a run that loads a session extends it. Its keyframes join
// the loaded graph, the loaded keyframes move with the new edges and their clouds with them, and
// the session it saves holds both runs' keyframes and a larger map.
TEST_F(DaemonSessions, InSlamModeALoadedSessionIsExtendedAndSavedAgain) {
  const std::string first = (dir_ / "first").string();
  const std::string extended = (dir_ / "extended").string();
  Config lap = smallSyntheticConfig(150);
  lap.set("synthetic.trajectory", "loop");
  lap.set("backend.enabled", "true");
  DaemonOverrides lap_outputs;
  lap_outputs.source = "synthetic:room";
  lap_outputs.session_out = first;
  runToEnd(lap, lap_outputs);

  Config more = smallSyntheticConfig(150);
  more.set("synthetic.trajectory", "random");
  more.set("synthetic.start_time_s", "1600001000");
  more.set("backend.enabled", "true");
  more.set("backend.mode", "slam");
  DaemonOverrides outputs;
  outputs.source = "synthetic:room";
  outputs.session_in = first;
  outputs.session_out = extended;
  const DaemonSummary second = runToEnd(more, outputs);
  EXPECT_GE(second.frames_before_localization, 0) << "never localised in the loaded map";

  const Session before = loadSession(first);
  const Session after = loadSession(extended);
  std::printf(
      "slam mode: %lld keyframes and %lld map voxels loaded, %lld and %lld saved\n",
      static_cast<long long>(before.info.keyframes), static_cast<long long>(before.info.map_voxels),
      static_cast<long long>(after.info.keyframes), static_cast<long long>(after.info.map_voxels));
  EXPECT_GT(after.info.keyframes, before.info.keyframes);
  EXPECT_GT(after.info.map_voxels, before.info.map_voxels);
  // The loaded keyframes stay in the graph; the session's first keyframe holds the gauge, the
  // others may move with the new edges (their clouds were restored, so the map follows them).
  std::size_t compared = 0;
  double largest_move_m = 0.0;
  for (const BackendSnapshot::Node& old_node : before.backend.nodes) {
    for (const BackendSnapshot::Node& new_node : after.backend.nodes) {
      if (new_node.id != old_node.id) continue;
      const double moved_m =
          (new_node.T_world_camera.translation() - old_node.T_world_camera.translation()).norm();
      if (old_node.fixed) {
        EXPECT_TRUE(new_node.fixed);
        EXPECT_LT(moved_m, 1e-9) << "the gauge keyframe moved";
      }
      largest_move_m = std::max(largest_move_m, moved_m);
      ++compared;
    }
  }
  EXPECT_EQ(compared, before.backend.nodes.size());
  EXPECT_LT(largest_move_m, 0.02) << "a loaded keyframe moved far: the runs disagree";
  // The saved map holds every keyframe's cloud where the final graph puts it, old ones included,
  // to within half a voxel (the mapper moves a cloud only when it would move farther).
  const double half_voxel_m = 0.5 * MappingConfig::load(more).resolution_m;
  ASSERT_FALSE(after.keyframe_clouds_path.empty());
  std::vector<KeyframeCloudRecord> clouds;
  std::string error;
  ASSERT_TRUE(readKeyframeCloudRecords(after.keyframe_clouds_path, clouds, &error)) << error;
  std::size_t loaded_clouds = 0;
  for (const KeyframeCloudRecord& cloud : clouds) {
    for (const BackendSnapshot::Node& node : after.backend.nodes) {
      if (node.id != cloud.id) continue;
      const SE3 T_difference = cloud.T_world_camera_in_map.inverse() * node.T_world_camera;
      double farthest_m = 0.0;
      for (const Eigen::Vector3f& point : cloud.cloud_camera.points) {
        farthest_m = std::max(farthest_m, static_cast<double>(point.norm()));
      }
      const double offset_m = T_difference.translation().norm() +
                              Eigen::AngleAxisd(T_difference.rotation()).angle() * farthest_m;
      EXPECT_LE(offset_m, half_voxel_m + 1e-9)
          << "keyframe " << cloud.id << "'s cloud is not where the graph puts it";
      if (cloud.id < before.backend.next_keyframe_id) ++loaded_clouds;
    }
  }
  EXPECT_EQ(loaded_clouds, before.backend.nodes.size());
  std::printf("slam mode: loaded keyframes moved up to %.4f m, their clouds with them\n",
              largest_move_m);
  // The new keyframes are numbered after the loaded ones.
  EXPECT_GE(after.backend.next_keyframe_id, before.backend.next_keyframe_id + 1);
}

// A session folder that is not one, a corrupt file, and another camera: each is refused before
// the run starts, with the file and the problem named.
TEST_F(DaemonSessions, BadSessionsAreRefusedBeforeTheRunStarts) {
  const std::string session = (dir_ / "room_session").string();
  {
    Config config = smallSyntheticConfig(60);
    config.set("backend.enabled", "true");
    DaemonOverrides overrides;
    overrides.source = "synthetic:room";
    overrides.session_out = session;
    runToEnd(config, overrides);
  }
  const auto load = [&](const std::string& dir, const std::vector<std::string>& assignments) {
    Config config = smallSyntheticConfig(10);
    config.set("backend.enabled", "true");
    for (const std::string& assignment : assignments) config.applyOverride(assignment);
    DaemonOverrides overrides;
    overrides.source = "synthetic:room";
    overrides.session_in = dir;
    try {
      SlamDaemon daemon(config, overrides);
      return std::string();
    } catch (const SessionError& e) {
      return std::string(e.what());
    }
  };
  EXPECT_EQ(load(session, {}), "") << "the session just written must load";
  // slamd-session-info reads it, and --verify loads it whole.
  const std::string info_out = (dir_ / "info.txt").string();
  const std::string info_tool =
      (std::filesystem::read_symlink("/proc/self/exe").parent_path() / "slamd-session-info")
          .string();
  const auto runInfo = [&](const std::string& arguments) {
    const int status =
        std::system((info_tool + " " + arguments + " > '" + info_out + "' 2>&1").c_str());
    std::ifstream in(info_out);
    std::stringstream text;
    text << in.rdbuf();
    return std::make_pair(WIFEXITED(status) ? WEXITSTATUS(status) : -1, text.str());
  };
  const auto [info_status, info_text] = runInfo("--verify '" + session + "'");
  EXPECT_EQ(info_status, 0) << info_text;
  EXPECT_NE(info_text.find("keyframes"), std::string::npos) << info_text;
  EXPECT_NE(info_text.find("OK"), std::string::npos) << info_text;

  const std::string missing = load((dir_ / "nowhere").string(), {});
  EXPECT_NE(missing.find("CURRENT"), std::string::npos) << missing;

  const std::string camera = load(session, {"camera.fx=300", "camera.fy=300"});
  EXPECT_NE(camera.find("another camera"), std::string::npos) << camera;

  // One byte of the graph flipped.
  const SessionInfo info = readSessionInfo(session);
  const std::filesystem::path graph =
      std::filesystem::path(session) / info.generation / kSessionGraphFile;
  {
    std::fstream file(graph, std::ios::in | std::ios::out | std::ios::binary);
    file.seekp(40);
    char byte = 0;
    file.seekg(40);
    file.read(&byte, 1);
    byte = static_cast<char>(byte ^ 0x5a);
    file.seekp(40);
    file.write(&byte, 1);
  }
  const std::string corrupt = load(session, {});
  EXPECT_NE(corrupt.find(kSessionGraphFile), std::string::npos) << corrupt;
  const auto [corrupt_status, corrupt_text] = runInfo("--verify '" + session + "'");
  EXPECT_EQ(corrupt_status, 1) << corrupt_text;
  EXPECT_NE(corrupt_text.find(kSessionGraphFile), std::string::npos) << corrupt_text;
}

}  // namespace
}  // namespace slamd
