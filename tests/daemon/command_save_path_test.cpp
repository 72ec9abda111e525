// SAVE_MAP paths from the network are confined to daemon.save_dir (hostile-input issue, row 6:
// any LCM peer could make slamd, running as root, create a file at any path ending in .bt).

#include "slamd/app/command_save_path.hpp"

#include <filesystem>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

namespace fs = std::filesystem;

class CommandSavePath : public ::testing::Test {
 protected:
  std::optional<std::string> resolve(const std::string& argument) {
    error_.clear();
    return resolveCommandSavePath(argument, dir_.string(), error_);
  }

  const test::ScopedTempDir temp_{"save-dir"};
  const fs::path dir_ = temp_.path();
  std::string error_;
};

TEST_F(CommandSavePath, ABareNameIsWrittenIntoTheSaveDirectory) {
  EXPECT_EQ(resolve("office_2026-12-02.bt"), (dir_ / "office_2026-12-02.bt").string());
  EXPECT_EQ(resolve("map.ot"), (dir_ / "map.ot").string());
}

TEST_F(CommandSavePath, AnAbsolutePathDirectlyInsideTheSaveDirectoryIsAccepted) {
  EXPECT_EQ(resolve((dir_ / "live.bt").string()), (dir_ / "live.bt").string());
  EXPECT_EQ(resolve((dir_ / "sub" / ".." / "live.bt").string()), (dir_ / "live.bt").string());
}

TEST_F(CommandSavePath, PathsOutsideTheSaveDirectoryAreRefusedSayingWhy) {
  fs::create_directories(dir_ / "inner");
  fs::create_symlink("/etc", dir_ / "link");
  for (const std::string& argument :
       {std::string("/etc/cron.d/x.bt"), std::string("/tmp/map.bt"), std::string("../escape.bt"),
        std::string("sub/map.bt"), (dir_ / ".." / "escape.bt").string(),
        (dir_ / "inner" / "map.bt").string(), (dir_ / "link" / "map.bt").string()}) {
    EXPECT_FALSE(resolve(argument).has_value()) << argument;
    EXPECT_NE(error_.find("refused"), std::string::npos) << error_;
    EXPECT_NE(error_.find(argument), std::string::npos) << "the error names the argument";
  }
}

TEST_F(CommandSavePath, NamesAreSanitised) {
  const std::string names[] = {"",       ".hidden.bt", "map.txt",
                               "map",    "map.bt\n",   "m\xC3\xA4p.bt",
                               "a b.bt", "map.bt;rm",  std::string(200, 'a') + ".bt"};
  for (const std::string& argument : names) {
    EXPECT_FALSE(resolve(argument).has_value()) << argument;
  }
}

TEST(CommandSavePathPolicy, AnEmptySaveDirectoryRefusesEveryName) {
  std::string error;
  EXPECT_FALSE(resolveCommandSavePath("map.bt", "", error).has_value());
  EXPECT_NE(error.find("daemon.save_dir"), std::string::npos) << error;
}

}  // namespace
}  // namespace slamd
