// Sessions end to end: a run saves its map, keyframes and pose graph (--session-out); a later run
// loads them (--session-in) and localises in that map, so its poses come out in the first run's
// frame. Bad sessions are refused before anything starts.

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "daemon_fixture.hpp"
#include "slamd/backend/session.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/trajectory_error.hpp"
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
}

}  // namespace
}  // namespace slamd
