#include "slamd/common/trajectory.hpp"

#include <fstream>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

TEST(Trajectory, ParsesCommentsWhitespaceAndCommas) {
  const Trajectory t = parseTumTrajectory(
      "# ground truth\n\n1305031098.6659 1.3563 0.6305 1.6380 0.6132 0.5962 -0.3311 -0.3986\n"
      "1305031098.6758,1.3543,0.6306,1.6360,0.6129,0.5966,-0.3316,-0.3980\r\n"
      "  1305031098.6858\t1 2 3 0 0 0 1\n");
  ASSERT_EQ(t.size(), 3u);
  EXPECT_DOUBLE_EQ(t[0].timestamp_s, 1305031098.6659);
  EXPECT_DOUBLE_EQ(t[0].T_world_camera.translation().x(), 1.3563);
  EXPECT_TRUE(t[2].T_world_camera.linear().isIdentity(1e-12));
}

TEST(Trajectory, MalformedLinesNameFileAndLine) {
  try {
    parseTumTrajectory("1 2 3\n", "gt.txt");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("gt.txt:1"), std::string::npos) << e.what();
  }
  EXPECT_THROW(parseTumTrajectory("1 2 3 4 5 6 7 x\n"), std::runtime_error);
  EXPECT_THROW(parseTumTrajectory("1 2 3 4 0 0 0 0\n"), std::runtime_error);
  EXPECT_THROW(parseTumTrajectory("1 2 3 4 0 0 0 1 9\n"), std::runtime_error);
  EXPECT_THROW(readTumTrajectory("/nonexistent/gt.txt"), std::runtime_error);
}

TEST(Trajectory, PathLengthSumsTheMovesAndDurationSpansTheStamps) {
  const Trajectory trajectory = parseTumTrajectory(
      "1.0 0 0 0 0 0 0 1\n"
      "1.5 3 4 0 0 0 0.7071068 0.7071068\n"  // 5 m away; rotation does not count
      "3.0 3 4 2 0 0 0 1\n");
  EXPECT_NEAR(pathLengthM(trajectory), 7.0, 1e-12);
  EXPECT_NEAR(durationS(trajectory), 2.0, 1e-12);
  EXPECT_EQ(pathLengthM(Trajectory(trajectory.begin(), trajectory.begin() + 1)), 0.0);
  EXPECT_EQ(durationS(Trajectory()), 0.0);
}

TEST(Trajectory, WriteThenReadRoundTrips) {
  Trajectory t;
  for (int i = 0; i < 10; ++i) {
    StampedPose p;
    p.timestamp_s = 1305031102.175304 + i / 30.0;
    p.T_world_camera = expSE3((Vector6d() << 0.1 * i, -0.2, 0.3, 0.01 * i, 0.2, -0.1).finished());
    t.push_back(p);
  }
  const test::ScopedTempDir dir("traj");
  const auto path = dir / "t.txt";
  writeTumTrajectory(path.string(), t, "written by a test\nsecond line");
  const Trajectory back = readTumTrajectory(path.string());
  ASSERT_EQ(back.size(), t.size());
  for (std::size_t i = 0; i < t.size(); ++i) {
    EXPECT_NEAR(back[i].timestamp_s, t[i].timestamp_s, 1e-6);
    EXPECT_LT((back[i].T_world_camera.matrix() - t[i].T_world_camera.matrix()).norm(), 1e-8);
  }
}

TEST(Trajectory, ReadsTheSharedGroundTruth) {
  const auto dir = test::findDataset("tum_fr1_xyz");
  if (!dir) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  const Trajectory gt = readTumTrajectory((*dir / "groundtruth.txt").string());
  EXPECT_EQ(gt.size(), 3000u);  // 3003 lines, 3 of them comments
  EXPECT_DOUBLE_EQ(gt.front().timestamp_s, 1305031098.6659);
}

}  // namespace
}  // namespace slamd
