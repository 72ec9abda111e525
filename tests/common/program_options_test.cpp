#include "slamd/common/program_options.hpp"

#include <fstream>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

TEST(ProgramOptions, ParsesConfigSetsOptionsFlagsAndPositionals) {
  const test::ScopedTempDir dir("options");
  const auto path = dir / "c.yaml";
  std::ofstream(path) << "tracking:\n  max_features: 500\n";
  ProgramOptions options("prog", "test");
  options.addOption("source", "SOURCE", "input", "synthetic:room");
  options.addFlag("publish", "publish");
  options.setPositional("FILE", 0, 1);
  const std::string config_arg = path.string();
  const char* argv[] = {"prog",
                        "--config",
                        config_arg.c_str(),
                        "--set",
                        "tracking.max_features=900",
                        "--set=tracking.frontend=sift",
                        "--publish",
                        "--source=tum:/x",
                        "file.txt"};
  ASSERT_TRUE(options.parse(9, argv));
  EXPECT_EQ(options.value("source"), "tum:/x");
  EXPECT_TRUE(options.flag("publish"));
  ASSERT_EQ(options.positional().size(), 1u);
  Config config = options.loadConfig();
  EXPECT_EQ(config.getInt("tracking.max_features", 0, 0, 10000), 900);
  EXPECT_EQ(config.getString("tracking.frontend", ""), "sift");
}

TEST(ProgramOptions, DefaultsApplyWhenAbsent) {
  ProgramOptions options("prog", "test");
  options.addOption("source", "SOURCE", "input", "synthetic:room");
  const char* argv[] = {"prog"};
  ASSERT_TRUE(options.parse(1, argv));
  EXPECT_EQ(options.value("source"), "synthetic:room");
  EXPECT_FALSE(options.has("source"));
}

TEST(ProgramOptions, UnknownOptionAndMissingValueAreUsageErrors) {
  {
    ProgramOptions options("prog", "test");
    const char* argv[] = {"prog", "--bogus"};
    EXPECT_FALSE(options.parse(2, argv));
    EXPECT_EQ(options.exitCode(), kExitUsage);
  }
  {
    ProgramOptions options("prog", "test");
    const char* argv[] = {"prog", "--config"};
    EXPECT_FALSE(options.parse(2, argv));
    EXPECT_EQ(options.exitCode(), kExitUsage);
  }
}

TEST(ProgramOptions, HelpExitsWithZero) {
  ProgramOptions options("prog", "test");
  const char* argv[] = {"prog", "--help"};
  EXPECT_FALSE(options.parse(2, argv));
  EXPECT_EQ(options.exitCode(), kExitOk);
  EXPECT_NE(options.usage().find("--set"), std::string::npos);
}

TEST(ReportConfig, AToolWarnsOnlyAboutTheSectionsItReads) {
  // A tool reading only camera.* from the daemon's file: a misspelt camera key is still named,
  // the daemon's filter keys are not its business.
  const auto make = [] {
    Config config = Config::fromYamlString(
        "camera:\n  fx: 500\n  fxx: 1\nfilter:\n  measurement_noise_scale: 0.6\n");
    config.getDouble("camera.fx", 525.0, 1.0, 1e4);
    return config;
  };
  testing::internal::CaptureStderr();
  reportConfig(make(), "tool", UnknownKeys::kInSectionsItRead);
  const std::string tool = testing::internal::GetCapturedStderr();
  EXPECT_NE(tool.find("'camera.fxx'"), std::string::npos) << tool;
  EXPECT_EQ(tool.find("filter.measurement_noise_scale"), std::string::npos) << tool;
  testing::internal::CaptureStderr();
  reportConfig(make(), "daemon");
  const std::string daemon = testing::internal::GetCapturedStderr();
  EXPECT_NE(daemon.find("'camera.fxx'"), std::string::npos) << daemon;
  EXPECT_NE(daemon.find("'filter.measurement_noise_scale'"), std::string::npos) << daemon;
}

}  // namespace
}  // namespace slamd
