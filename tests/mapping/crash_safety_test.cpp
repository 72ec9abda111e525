// kill -9 at random moments while the mapper saves: 100 trials. A child process maps a room and
// saves without pause, alternating the periodic snapshot (.ot) and a map save (.bt), and reports
// each save it completed through a pipe; the parent kills it (SIGKILL) at a random moment. After
// each kill, each file must be complete and loadable, and be either the last version the child
// reported as saved or the one it was writing (renamed into place just before the kill): nothing
// saved is ever lost or torn. A temporary file left by the kill is removed by the start-up
// cleanup, as the daemon does.

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "box_room.hpp"
#include "scoped_temp_dir.hpp"
#include "slamd/common/file_io.hpp"
#include "slamd/mapping/mapper.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

namespace fs = std::filesystem;

std::uint64_t fileHash(const std::string& path) {
  std::vector<std::uint8_t> bytes;
  std::string error;
  if (!readFileBytes(path, bytes, error)) return 0;
  std::uint64_t hash = 14695981039346656037ull;
  for (std::uint8_t b : bytes) hash = (hash ^ b) * 1099511628211ull;
  return hash;
}

MappingConfig childConfig(const fs::path& dir) {
  MappingConfig config;
  config.resolution_m = 0.1;
  config.update_rate_hz = 0.0;
  config.full_map_period_s = 0.0;
  config.snapshot_period_s = 0.0;  // saveSnapshot() is called directly
  config.snapshot_path = (dir / "snapshot.ot").string();
  config.keep_keyframe_clouds = false;  // a plain map (no back end): clamped log-odds
  return config;
}

/// The child: maps and saves until killed. Reports "saving PATH" before and "saved PATH HASH
/// MICROSECONDS" after every save.
[[noreturn]] void mapAndSaveForever(const fs::path& dir, int report_fd) {
  const auto report = [report_fd](const std::string& line) {
    const std::string text = line + "\n";
    if (::write(report_fd, text.data(), text.size()) < 0) _exit(3);
  };
  Mapper mapper(childConfig(dir));
  const std::string map_path = (dir / "map.bt").string();
  const test::BoxRoom room;
  const auto poses = test::lookAroundPoses(8);
  const CameraIntrinsics intrinsics = CameraIntrinsics{}.scaled(80, 60);
  std::vector<RgbdFrame> frames;
  for (const SE3& pose : poses) frames.push_back(room.render(pose, intrinsics));
  // Mostly saving, so that most kills land inside a save: one frame mapped per four saves.
  for (std::size_t i = 0;; ++i) {
    if (i % 4 == 0) {
      const std::size_t k = (i / 4) % frames.size();
      frames[k].utime = 1'000'000 + static_cast<Utime>(i) * 33'333;
      mapper.integrate(frames[k], poses[k]);
    }
    const bool snapshot = i % 2 == 0;
    const std::string path = snapshot ? mapper.config().snapshot_path : map_path;
    report("saving " + path);
    const auto start = std::chrono::steady_clock::now();
    const MapFileResult result = snapshot ? mapper.saveSnapshot() : mapper.saveMap(map_path);
    const auto took_us = std::chrono::duration_cast<std::chrono::microseconds>(
                             std::chrono::steady_clock::now() - start)
                             .count();
    if (!result.ok) _exit(4);
    report("saved " + path + " " + std::to_string(fileHash(path)) + " " + std::to_string(took_us));
  }
}

struct SaveLog {
  std::map<std::string, std::uint64_t> last_saved_hash;
  std::map<std::string, bool> writing;  ///< "saving" reported after the last "saved"
  long long last_save_us = 0;           ///< how long the last completed save took
};

void parseReports(const std::string& text, SaveLog& log) {
  std::istringstream lines(text);
  std::string word, path;
  while (lines >> word >> path) {
    if (word == "saving") {
      log.writing[path] = true;
    } else {
      std::uint64_t hash = 0;
      long long took_us = 0;
      lines >> hash >> took_us;
      log.last_saved_hash[path] = hash;
      log.last_save_us = took_us;
      log.writing[path] = false;
    }
  }
}

TEST(MapSaveCrashSafety, KillNineAtRandomMomentsNeverLosesOrTearsASavedMap) {
  constexpr int kTrials = 100;
  const test::ScopedTempDir dir("kill9");
  std::mt19937 random(20261202);
  int torn_temporaries = 0;
  int newer_than_reported = 0;
  for (int trial = 0; trial < kTrials; ++trial) {
    int fds[2];
    ASSERT_EQ(::pipe(fds), 0);
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      ::close(fds[0]);
      mapAndSaveForever(dir, fds[1]);
    }
    ::close(fds[1]);
    // Wait for a completed save (to know how long one takes on this machine, sanitizers and
    // load included) and for the next save to start, then kill at a random moment within
    // 1.25 save durations: inside the save, or just after it.
    std::string reports;
    char buffer[4096];
    const auto nextSaveStarted = [&reports] {
      const auto saved = reports.find("saved");
      return saved != std::string::npos && reports.find("saving", saved) != std::string::npos;
    };
    while (!nextSaveStarted()) {
      const ssize_t n = ::read(fds[0], buffer, sizeof(buffer));
      ASSERT_GT(n, 0) << "the child stopped before saving (trial " << trial << ")";
      reports.append(buffer, static_cast<std::size_t>(n));
    }
    SaveLog so_far;
    parseReports(reports, so_far);
    const auto window_us = static_cast<int>(1.25 * static_cast<double>(so_far.last_save_us)) + 1;
    std::this_thread::sleep_for(
        std::chrono::microseconds(std::uniform_int_distribution<int>(0, window_us)(random)));
    ASSERT_EQ(::kill(child, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(::waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
        << "the child exited by itself (status " << status << ", trial " << trial << ")";
    ssize_t n = 0;
    while ((n = ::read(fds[0], buffer, sizeof(buffer))) > 0) {
      reports.append(buffer, static_cast<std::size_t>(n));
    }
    ::close(fds[0]);
    SaveLog log;
    parseReports(reports, log);

    for (const fs::path& file : {dir / "snapshot.ot", dir / "map.bt"}) {
      const std::string path = file.string();
      if (!fs::exists(file)) continue;  // not saved yet in any trial
      // Whatever is on disk is a complete map...
      MappingConfig config = childConfig(dir);
      config.snapshot_path.clear();
      config.load_path = path;
      ASSERT_NO_THROW({ Mapper reloaded(config); }) << path << " is torn (trial " << trial << ")";
      // ...and the last one reported saved, unless the save in progress had just replaced it.
      const auto saved = log.last_saved_hash.find(path);
      if (saved != log.last_saved_hash.end() && fileHash(path) != saved->second) {
        ASSERT_TRUE(log.writing[path]) << path << " changed without a save (trial " << trial << ")";
        ++newer_than_reported;
      }
    }
    // The start-up cleanup removes a temporary file the kill left.
    const auto removed =
        removeStaleTemporaryFiles({(dir / "snapshot.ot").string(), (dir / "map.bt").string()});
    torn_temporaries += static_cast<int>(removed.size());
    for (const auto& entry : fs::directory_iterator(dir)) {
      EXPECT_NE(entry.path().extension(), ".tmp") << entry.path() << " left after the cleanup";
    }
  }
  // The kills must really land during saves for the test to mean something. On this machine
  // class 24-38 of 100 land mid-write (the rest just after the rename, or in the fsync of the
  // folder); a quarter was too close to that to hold in every run.
  EXPECT_GE(torn_temporaries, kTrials / 10);
  std::printf(
      "%d kill -9 trials: %d killed mid-write (temporary file left and removed), %d just "
      "after a rename, 0 saved maps lost or torn\n",
      kTrials, torn_temporaries, newer_than_reported);
}

}  // namespace
}  // namespace slamd
