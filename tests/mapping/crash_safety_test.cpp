// kill -9 at random moments while the mapper saves: 100 trials. A child process maps a room and
// saves without pause, alternating the periodic snapshot (.ot) and a map save (.bt), and reports
// each save it completed through a pipe; the parent kills it (SIGKILL) at a random moment. After
// each kill, each file must be complete and loadable, and be either the last version the child
// reported as saved or the one it was writing (renamed into place just before the kill): nothing
// saved is ever lost or torn. A temporary file left by the kill is removed by the start-up
// cleanup, as the daemon does.

#include <gtest/gtest.h>
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

#include "box_room.hpp"
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
  return config;
}

/// The child: maps and saves until killed. Reports "saving PATH" before and "saved PATH HASH"
/// after every save.
[[noreturn]] void mapAndSaveForever(const fs::path& dir, int report_fd) {
  const auto report = [report_fd](const std::string& line) {
    const std::string text = line + "\n";
    if (::write(report_fd, text.data(), text.size()) < 0) _exit(3);
  };
  Mapper mapper(childConfig(dir));
  const std::string map_path = (dir / "map.bt").string();
  const test::BoxRoom room;
  const auto poses = test::lookAroundPoses(8);
  const CameraIntrinsics intrinsics = CameraIntrinsics{}.scaled(160, 120);
  for (std::size_t i = 0;; ++i) {
    RgbdFrame frame = room.render(poses[i % poses.size()], intrinsics);
    frame.utime = 1'000'000 + static_cast<Utime>(i) * 33'333;
    mapper.integrate(frame, poses[i % poses.size()]);
    const bool snapshot = i % 2 == 0;
    const std::string path = snapshot ? mapper.config().snapshot_path : map_path;
    report("saving " + path);
    const MapFileResult result = snapshot ? mapper.saveSnapshot() : mapper.saveMap(map_path);
    if (!result.ok) _exit(4);
    report("saved " + path + " " + std::to_string(fileHash(path)));
  }
}

struct SaveLog {
  std::map<std::string, std::uint64_t> last_saved_hash;
  std::map<std::string, bool> writing;  ///< "saving" reported after the last "saved"
};

void parseReports(const std::string& text, SaveLog& log) {
  std::istringstream lines(text);
  std::string word, path;
  while (lines >> word >> path) {
    if (word == "saving") {
      log.writing[path] = true;
    } else {
      std::uint64_t hash = 0;
      lines >> hash;
      log.last_saved_hash[path] = hash;
      log.writing[path] = false;
    }
  }
}

TEST(MapSaveCrashSafety, KillNineAtRandomMomentsNeverLosesOrTearsASavedMap) {
  constexpr int kTrials = 100;
  const fs::path dir = test::makeTempDir("kill9");
  std::mt19937 random(20261202);
  // Most of the child's time is spent saving; the delays spread the kills over whole cycles.
  std::uniform_int_distribution<int> delay_us(0, 120'000);
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
    // Wait for the first completed save of this trial, then kill at a random moment.
    std::string reports;
    char buffer[4096];
    while (reports.find("saved") == std::string::npos) {
      const ssize_t n = ::read(fds[0], buffer, sizeof(buffer));
      ASSERT_GT(n, 0) << "the child stopped before saving (trial " << trial << ")";
      reports.append(buffer, static_cast<std::size_t>(n));
    }
    std::this_thread::sleep_for(std::chrono::microseconds(delay_us(random)));
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
    const auto removed = removeStaleTemporaryFiles(
        {(dir / "snapshot.ot").string(), (dir / "map.bt").string()});
    torn_temporaries += static_cast<int>(removed.size());
    for (const auto& entry : fs::directory_iterator(dir)) {
      EXPECT_NE(entry.path().extension(), ".tmp") << entry.path() << " left after the cleanup";
    }
  }
  // The kills must really land during saves for the test to mean something.
  EXPECT_GT(torn_temporaries, kTrials / 4);
  std::printf("%d kill -9 trials: %d killed mid-write (temporary file left and removed), %d just "
              "after a rename, 0 saved maps lost or torn\n",
              kTrials, torn_temporaries, newer_than_reported);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace slamd
