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

}  // namespace
}  // namespace slamd
