// slamd-export on LCM logs written here with known content: every output reads back as what was
// logged; malformed messages are skipped and counted; a missing channel, a missing log and an
// unwritable output each give their exit code and a message that names the problem.

#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>
#include <octomap/OcTree.h>

#include "scoped_temp_dir.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/mapping/map_io.hpp"
#include "slamd/status_t.hpp"

namespace slamd {
namespace {

#ifdef SLAMD_EXPORT_PATH

constexpr Utime kStartUtime = 1'700'000'000'000'000;
constexpr int kPoses = 5;

SE3 posesAt(int i) {
  return makeSE3(
      Eigen::Vector3d(0.1 * i, -0.02 * i, 0.3 + 0.01 * i),
      Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d(0.3, 1, 0.2).normalized())));
}

class LogWriter {
 public:
  explicit LogWriter(const std::string& path) : log_(path, "w") {}
  template <typename Message>
  void write(const std::string& channel, const Message& message) {
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(message.getEncodedSize()));
    message.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
    writeBytes(channel, bytes);
  }
  void writeBytes(const std::string& channel, std::vector<std::uint8_t> bytes) {
    lcm::LogEvent event;
    event.eventnum = events_++;
    event.timestamp = kStartUtime + events_ * 1000;
    event.channel = channel;
    event.datalen = static_cast<std::int32_t>(bytes.size());
    event.data = bytes.data();
    ASSERT_EQ(log_.writeEvent(&event), 0);
  }

 private:
  lcm::LogFile log_;
  std::int64_t events_ = 0;
};

/// A log of a short run: poses on SLAMD_POSE and POSE, two map updates, a keyframe trajectory,
/// two status messages, and one malformed message on each of three channels.
void writeRunLog(const std::string& path, bool with_keyframes) {
  LogWriter log(path);
  for (int i = 0; i < kPoses; ++i) {
    PoseEstimate pose;
    pose.utime = kStartUtime + i * 33'333;
    pose.sequence = i;
    pose.T_world_camera = posesAt(i);
    pose.covariance = Matrix6d::Identity() * (1e-4 * (i + 1));
    pose.tracking_state = TrackingState::kOk;
    log.write("SLAMD_POSE", toPoseMessage(pose));
    log.write("POSE", toBotCorePose(pose));
    if (i == 2) log.writeBytes("SLAMD_POSE", {1, 2, 3, 4, 5, 6, 7});
  }
  MapUpdate update;
  update.resolution_m = 0.05;
  update.frame_id = "world";
  update.voxels = {{Eigen::Vector3f(0.025f, 0.025f, 1.025f), 2.0f},
                   {Eigen::Vector3f(0.125f, 0.025f, 1.025f), 2.0f},
                   {Eigen::Vector3f(0.125f, 0.125f, 1.025f), -1.0f}};
  log.write("SLAMD_MAP_UPDATE", toMapUpdateMessage(update));
  update.sequence = 1;
  update.voxels = {{Eigen::Vector3f(0.225f, 0.025f, 1.025f), 1.5f}};
  log.write("SLAMD_MAP_UPDATE", toMapUpdateMessage(update));
  log.writeBytes("SLAMD_MAP_UPDATE", std::vector<std::uint8_t>(40, 0xff));
  if (with_keyframes) {
    KeyframeTrajectory keyframes;
    for (int i = 0; i < kPoses; i += 2) {
      keyframes.keyframes.push_back({i, kStartUtime + i * 33'333, 0, posesAt(i)});
    }
    log.write("SLAMD_KEYFRAMES", toKeyframeTrajectoryMessage(keyframes));
  }
  for (int k = 0; k < 2; ++k) {
    slamd::status_t status;
    status.utime = kStartUtime + k * 1'000'000;
    for (const char* name : {"capture", "tracking"}) {
      slamd::stage_status_t stage;
      stage.name = name;
      stage.rate_hz = 30.0;
      stage.latency_p50_ms = 12.5 + k;
      stage.processed = 30 * (k + 1);
      status.stages.push_back(stage);
    }
    status.num_stages = static_cast<std::int32_t>(status.stages.size());
    status.tracking_state = static_cast<std::int8_t>(TrackingState::kOk);
    status.message = "";
    log.write("SLAMD_STATUS", status);
  }
  log.writeBytes("SLAMD_STATUS", {0, 0, 0});
}

struct RunResult {
  int exit_code = -1;
  std::string output;  ///< stdout and stderr
};

RunResult runExport(const std::string& arguments, const std::filesystem::path& dir) {
  const std::filesystem::path output = dir / "export.out";
  const std::string command =
      std::string(SLAMD_EXPORT_PATH) + " " + arguments + " > " + output.string() + " 2>&1";
  const int status = std::system(command.c_str());
  RunResult result;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(output);
  std::stringstream text;
  text << in.rdbuf();
  result.output = text.str();
  return result;
}

std::vector<std::string> lines(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<std::string> out;
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

void expectPosesEqual(const Trajectory& trajectory) {
  ASSERT_EQ(trajectory.size(), static_cast<std::size_t>(kPoses));
  for (int i = 0; i < kPoses; ++i) {
    const StampedPose& pose = trajectory[static_cast<std::size_t>(i)];
    EXPECT_NEAR(pose.timestamp_s, utimeToSeconds(kStartUtime + i * 33'333), 1e-6);
    EXPECT_LT((pose.T_world_camera.translation() - posesAt(i).translation()).norm(), 1e-8);
    EXPECT_LT((pose.T_world_camera.linear() - posesAt(i).linear()).norm(), 1e-8);
  }
}

TEST(SlamdExport, EveryOutputReadsBackAsWhatWasLogged) {
  const test::ScopedTempDir dir("slamd-export");
  const std::string log = (dir / "run.lcmlog").string();
  writeRunLog(log, true);
  const RunResult run =
      runExport(log + " --trajectory " + (dir / "t.txt").string() + " --trajectory-csv " +
                    (dir / "t.csv").string() + " --map " + (dir / "map.bt").string() +
                    " --map-ply " + (dir / "map.ply").string() + " --keyframes " +
                    (dir / "kf.txt").string() + " --keyframes-ply " + (dir / "kf.ply").string() +
                    " --status-csv " + (dir / "status.csv").string(),
                dir);
  ASSERT_EQ(run.exit_code, kExitOk) << run.output;
  EXPECT_NE(run.output.find("1 malformed messages on SLAMD_POSE"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("1 malformed messages on SLAMD_MAP_UPDATE"), std::string::npos);
  EXPECT_NE(run.output.find("1 malformed messages on SLAMD_STATUS"), std::string::npos);

  expectPosesEqual(readTumTrajectory((dir / "t.txt").string()));
  const auto csv = lines(dir / "t.csv");
  ASSERT_EQ(csv.size(), static_cast<std::size_t>(kPoses + 1));
  EXPECT_EQ(csv[0], kPoseCsvHeader);
  EXPECT_NE(csv[3].find(",3.000e-04,3.000e-04,"), std::string::npos) << csv[3];  // pose 2
  EXPECT_NE(csv[3].find(",ok,"), std::string::npos) << csv[3];

  // The map: both updates applied, the free voxel not in the cloud.
  octomap::OcTree tree(0.1);
  ASSERT_TRUE(tree.readBinary((dir / "map.bt").string()));
  EXPECT_DOUBLE_EQ(tree.getResolution(), 0.05);
  for (const auto& [x, occupied] : {std::pair{0.025, true}, {0.125, true}, {0.225, true}}) {
    const octomap::OcTreeNode* node = tree.search(x, 0.025, 1.025);
    ASSERT_NE(node, nullptr) << x;
    EXPECT_EQ(tree.isNodeOccupied(node), occupied) << x;
  }
  const octomap::OcTreeNode* free_node = tree.search(0.125, 0.125, 1.025);
  ASSERT_NE(free_node, nullptr);
  EXPECT_FALSE(tree.isNodeOccupied(free_node));
  PointCloud map_cloud;
  ASSERT_TRUE(readPly((dir / "map.ply").string(), map_cloud));
  EXPECT_EQ(map_cloud.size(), 3u);

  const Trajectory keyframes = readTumTrajectory((dir / "kf.txt").string());
  ASSERT_EQ(keyframes.size(), 3u);
  EXPECT_LT((keyframes[2].T_world_camera.translation() - posesAt(4).translation()).norm(), 1e-8);
  PointCloud keyframe_cloud;
  ASSERT_TRUE(readPly((dir / "kf.ply").string(), keyframe_cloud));
  EXPECT_EQ(keyframe_cloud.size(), 3u);

  const auto status = lines(dir / "status.csv");
  ASSERT_EQ(status.size(), 5u);  // header, 2 messages x 2 stages
  EXPECT_EQ(status[0].rfind("utime,stage,rate_hz,latency_p50_ms", 0), 0u);
  EXPECT_EQ(status[4].rfind(std::to_string(kStartUtime + 1'000'000) + ",tracking,30.000,13.500", 0),
            0u)
      << status[4];
}

TEST(SlamdExport, ReadsBotCorePosesFromThePoseChannel) {
  const test::ScopedTempDir dir("slamd-export-bot");
  const std::string log = (dir / "run.lcmlog").string();
  writeRunLog(log, false);
  const RunResult run =
      runExport(log + " --pose-channel POSE --trajectory " + (dir / "bot.txt").string(), dir);
  ASSERT_EQ(run.exit_code, kExitOk) << run.output;
  expectPosesEqual(readTumTrajectory((dir / "bot.txt").string()));
  EXPECT_EQ(lines(dir / "bot.txt")[0], "# slamd-export: bot_core.pose_t on POSE");
}

TEST(SlamdExport, NamesWhatIsMissingAndFailsWithTheProjectsExitCodes) {
  const test::ScopedTempDir dir("slamd-export-bad");
  const std::string log = (dir / "run.lcmlog").string();
  writeRunLog(log, false);
  // No keyframes in the log: exit 4, naming the channel and listing the log's channels; the
  // outputs that have data are still written.
  RunResult run = runExport(log + " --keyframes " + (dir / "kf.txt").string() + " --trajectory " +
                                (dir / "t.txt").string(),
                            dir);
  EXPECT_EQ(run.exit_code, kExitSourceError) << run.output;
  EXPECT_NE(run.output.find("no decodable keyframe trajectory on SLAMD_KEYFRAMES"),
            std::string::npos)
      << run.output;
  EXPECT_NE(run.output.find("SLAMD_POSE (6)"), std::string::npos) << run.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "kf.txt"));
  EXPECT_TRUE(std::filesystem::exists(dir / "t.txt"));

  run = runExport(log, dir);
  EXPECT_EQ(run.exit_code, kExitUsage) << run.output;
  run = runExport((dir / "absent.lcmlog").string() + " --trajectory t.txt", dir);
  EXPECT_EQ(run.exit_code, kExitSourceError) << run.output;
  EXPECT_NE(run.output.find("absent.lcmlog"), std::string::npos) << run.output;
  run = runExport(log + " --trajectory " + (dir / "missing-folder" / "t.txt").string(), dir);
  EXPECT_EQ(run.exit_code, kExitOutputError) << run.output;
  run = runExport(log + " --map " + (dir / "map.png").string(), dir);
  EXPECT_EQ(run.exit_code, kExitOutputError) << run.output;
  EXPECT_NE(run.output.find("must end in .bt or .ot"), std::string::npos) << run.output;
}

#else
TEST(SlamdExport, NotBuilt) { GTEST_SKIP() << "slamd-export is not built in this tree"; }
#endif

}  // namespace
}  // namespace slamd
