#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "slamd/common/trajectory.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

#ifdef SLAMD_SYNTH_PROGRAM

int run(const std::string& arguments) {
  const std::string command = std::string(SLAMD_SYNTH_PROGRAM) + " " + arguments + " 2>/dev/null";
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

int countLines(const std::filesystem::path& path) {
  std::ifstream file(path);
  int lines = 0;
  for (std::string line; std::getline(file, line);) {
    if (!line.empty() && line[0] != '#') ++lines;
  }
  return lines;
}

TEST(SlamdSynthProgram, WritesATumFolderWithTheRequestedFrames) {
  const test::ScopedTempDir dir("synth-cli");
  ASSERT_EQ(run("--scene room --trajectory robot --frames 4 --seed 3 --out " + dir.string()), 0);
  EXPECT_EQ(countLines(dir / "rgb.txt"), 4);
  EXPECT_EQ(countLines(dir / "depth.txt"), 4);
  const Trajectory gt = readTumTrajectory((dir / "groundtruth.txt").string());
  ASSERT_EQ(gt.size(), 4u);
  EXPECT_NEAR(gt[1].timestamp_s - gt[0].timestamp_s, 1.0 / 30.0, 1e-6);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir / "depth"),
                          std::filesystem::directory_iterator()),
            4);
}

TEST(SlamdSynthProgram, ReportsBadScenesValuesAndFoldersWithDistinctExitCodes) {
  const test::ScopedTempDir dir("synth-cli");
  EXPECT_EQ(run("--scene castle --frames 1 --out " + dir.string()), 4);
  EXPECT_EQ(run("--scene room --frames -3 --out " + dir.string()), 3);
  EXPECT_EQ(run("--scene room --trajectory spiral --out " + dir.string()), 3);
  EXPECT_EQ(run("--scene room --frames 1 --out /proc/slamd-no-such-dir"), 5);
  EXPECT_EQ(run("--scene room"), 2);
}

#endif

}  // namespace
}  // namespace slamd
