// End to end over real LCM UDP multicast, inside a private network namespace made by the test:
// slamd-play publishes a TUM folder as slamd.rgbd_frame_t while the real lcm-logger records and a
// second slamd-play receives live; then lcm-logplayer replays the log into a third slamd-play.
// All three list every frame (sequence, utime, depth and colour sums): the lists must be equal.

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "test_data.hpp"
#include "tum_fixture.hpp"

namespace slamd {
namespace {

std::vector<std::string> frameLines(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("frame ", 0) == 0) lines.push_back(line);
  }
  return lines;
}

bool commandExists(const std::string& name) {
  return std::system(("command -v " + name + " > /dev/null 2>&1").c_str()) == 0;
}

TEST(LcmLogReplay, LoggedAndReplayedFramesEqualThePublishedOnes) {
#ifndef SLAMD_PLAY_PATH
  GTEST_SKIP() << "slamd-play is not built in this tree; skipping";
#else
  if (geteuid() != 0) GTEST_SKIP() << "needs root for unshare -n; skipping";
  for (const char* tool : {"unshare", "ip", "lcm-logger", "lcm-logplayer"}) {
    if (!commandExists(tool)) GTEST_SKIP() << tool << " not installed; skipping";
  }
  constexpr int kFrames = 6;
  const auto folder = test::writeTumFolder("lcm-replay-data", kFrames, false);
  const test::ScopedTempDir dir("lcm-replay");
  const std::string play = SLAMD_PLAY_PATH;
  const std::string common =
      " --lcm-url \"$URL\" --list --set camera.width=64 --set camera.height=48"
      " --set camera.cx=31.5 --set camera.cy=23.5 --set capture.preprocess.range_gate=false"
      " --set capture.preprocess.flying_pixels=false --set play.timeout_s=20";
  const std::string receive = play + " --source lcm:SLAMD_TEST_FRAMES" + common +
                              " --set play.max_frames=" + std::to_string(kFrames);
  std::ostringstream script;
  // Waiting for a condition (a multicast group joined on lo) with a deadline, not a fixed sleep.
  script << "set -e\n"
         << "ip link set lo up\n"
         << "ip route add 224.0.0.0/4 dev lo\n"
         << "URL='udpm://239.255.76.67:7667?ttl=0'\n"
         // lcm-logger and lcm-logplayer take the URL from the environment.
         << "export LCM_DEFAULT_URL=\"$URL\"\n"
         << "joined() { ip maddr show dev lo | grep -c 239.255.76.67 || true; }\n"
         << "wait_joined() { for i in $(seq 500); do [ \"$(joined)\" -ge \"$1\" ] && return 0;"
            " sleep 0.01; done; echo 'multicast group not joined' >&2; return 1; }\n"
         << "cd " << dir << "\n"
         << "lcm-logger -c SLAMD_TEST_FRAMES -f frames.lcmlog > logger.txt 2>&1 &\n"
         << "LOGGER=$!\n"
         << receive << " > live.txt 2> live.err &\n"
         << "LIVE=$!\n"
         << "wait_joined 1\n"
         // Both listeners share the group; give the second its own check through its socket.
         << "for i in $(seq 500); do [ \"$(ss -ulpn 2>/dev/null | grep -c 7667)\" -ge 2 ] && break;"
            " sleep 0.01; done\n"
         << "kill -0 $LOGGER\n"
         << play << " --source tum:" << folder.dir.string() << common
         << " --publish --set capture.publish.channel=SLAMD_TEST_FRAMES"
            " --set capture.publish.color=png --set capture.publish.depth_scale=5000"
            " --set capture.pacing.mode=fixed --set capture.pacing.rate_hz=30"
            " > sent.txt 2> sent.err\n"
         << "wait $LIVE\n"
         << "kill -INT $LOGGER\n"
         << "wait $LOGGER || true\n"
         << receive << " --set capture.lcm.idle_end_s=5 > replay.txt 2> replay.err &\n"
         << "REPLAY=$!\n"
         << "wait_joined 1\n"
         << "for i in $(seq 500); do [ \"$(ss -ulpn 2>/dev/null | grep -c 7667)\" -ge 1 ] && break;"
            " sleep 0.01; done\n"
         << "lcm-logplayer frames.lcmlog\n"
         << "wait $REPLAY\n";
  const std::filesystem::path script_path = dir / "run.sh";
  std::ofstream(script_path) << script.str();
  const std::string command = "timeout 120 unshare -n bash " + script_path.string() + " > " +
                              (dir / "run.log").string() + " 2>&1";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
      << "script failed, see " << dir / "run.log"
      << " and *.err in " << dir;

  const auto sent = frameLines(dir / "sent.txt");
  const auto live = frameLines(dir / "live.txt");
  const auto replay = frameLines(dir / "replay.txt");
  ASSERT_EQ(sent.size(), static_cast<std::size_t>(kFrames));
  EXPECT_EQ(live, sent) << "received live over UDP multicast";
  EXPECT_EQ(replay, sent) << "replayed from the lcm-logger log by lcm-logplayer";
  EXPECT_GT(std::filesystem::file_size(dir / "frames.lcmlog"), 0u);
#endif
}

}  // namespace
}  // namespace slamd
