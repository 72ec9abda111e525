// The tests' temporary folders: removed at scope exit unless kept.

#include "scoped_temp_dir.hpp"

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace slamd {
namespace {

namespace fs = std::filesystem;

TEST(ScopedTempDir, IsRemovedWithItsContentAtScopeExit) {
  fs::path where;
  {
    const test::ScopedTempDir dir("scoped");
    where = dir.path();
    ASSERT_TRUE(fs::is_directory(where));
    EXPECT_TRUE(fs::is_empty(where));
    fs::create_directories(dir / "sub");
    std::ofstream(dir / "sub" / "file.txt") << "content";
  }
  EXPECT_FALSE(fs::exists(where));
}

TEST(ScopedTempDir, MovingHandsOverTheFolder) {
  test::ScopedTempDir first("scoped-move");
  const fs::path where = first.path();
  {
    test::ScopedTempDir second(std::move(first));
    EXPECT_EQ(second.path(), where);
    EXPECT_TRUE(fs::is_directory(where));
  }
  EXPECT_FALSE(fs::exists(where));
}

TEST(ScopedTempDir, KeepAndTheEnvironmentVariableLeaveItInPlace) {
  fs::path kept;
  {
    test::ScopedTempDir dir("scoped-keep");
    kept = dir.path();
    dir.keep();
  }
  EXPECT_TRUE(fs::is_directory(kept));
  fs::remove_all(kept);

  ::setenv("SLAMD_KEEP_TEST_DIRS", "1", 1);
  {
    const test::ScopedTempDir dir("scoped-env");
    kept = dir.path();
  }
  ::unsetenv("SLAMD_KEEP_TEST_DIRS");
  EXPECT_TRUE(fs::is_directory(kept));
  fs::remove_all(kept);
}

}  // namespace
}  // namespace slamd
