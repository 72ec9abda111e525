// Output files: failures are reported with the reason, never silent (hostile-input issue,
// row 10: --trajectory-out /dev/full said "written" and exited 0 with a truncated file).

#include "slamd/common/file_io.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

bool writeText(const std::string& path, const std::string& text, std::string* error) {
  return writeOutputFile(
      path,
      [&](std::ostream& out) {
        out << text;
        return true;
      },
      error);
}

TEST(FileIo, ANewFileIsWrittenWhole) {
  const test::ScopedTempDir dir("file-io");
  const std::string path = (dir / "out.txt").string();
  std::string error;
  ASSERT_TRUE(writeText(path, std::string(300000, 'x'), &error)) << error;
  EXPECT_EQ(std::filesystem::file_size(path), 300000u);
  EXPECT_FALSE(std::filesystem::exists(temporaryPathFor(path)));
}

TEST(FileIo, AFullDeviceIsAnErrorWithTheReason) {
  std::string error;
  EXPECT_FALSE(writeText("/dev/full", std::string(300000, 'x'), &error));
  EXPECT_NE(error.find("/dev/full"), std::string::npos) << error;
  EXPECT_NE(error.find("No space left on device"), std::string::npos) << error;
  EXPECT_TRUE(std::filesystem::is_character_file("/dev/full")) << "the device node is untouched";
}

TEST(FileIo, AMissingFolderOrADirectoryIsAnErrorNamingThePath) {
  const test::ScopedTempDir dir("file-io");
  std::string error;
  EXPECT_FALSE(writeText((dir / "missing" / "out.txt").string(), "x", &error));
  EXPECT_NE(error.find("No such file or directory"), std::string::npos) << error;
  EXPECT_FALSE(writeText(dir.string(), "x", &error));
  EXPECT_NE(error.find("directory"), std::string::npos) << error;
}

}  // namespace
}  // namespace slamd
