#pragma once
// The in-process daemon fixture: a small (320x240) synthetic world, in-process LCM (memq://), a
// temporary folder for outputs.

#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "slamd/app/slam_daemon.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/shutdown_signals.hpp"

namespace slamd {

class DaemonInProcess : public ::testing::Test {
 protected:
  void SetUp() override { setLogLevel(LogLevel::kWarn); }
  void TearDown() override { setLogLevel(LogLevel::kInfo); }

  Config smallSyntheticConfig(int frames) {
    Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/synthetic.yaml");
    for (const char* assignment :
         {"camera.width=320", "camera.height=240", "camera.fx=262.5", "camera.fy=262.5",
          "camera.cx=159.5", "camera.cy=119.5", "lcm.url=memq://"}) {
      config.applyOverride(assignment);
    }
    config.set("synthetic.frames", std::to_string(frames));
    return config;
  }

  /// Runs a daemon over the whole source; expects exit code 0 and returns its summary.
  DaemonSummary runToEnd(Config& config, const DaemonOverrides& overrides) {
    ShutdownSignals signals;
    SlamDaemon daemon(config, overrides);
    EXPECT_EQ(daemon.run(signals), kExitOk);
    return daemon.summary();
  }

  const test::ScopedTempDir temp_{"daemon"};  // removed with the fixture
  const std::filesystem::path dir_ = temp_.path();
};

}  // namespace slamd
