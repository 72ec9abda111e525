#include <sys/stat.h>

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "slamd/capture/image_io.hpp"
#include "slamd/capture/tum_source.hpp"
#include "tum_fixture.hpp"

namespace slamd {
namespace {

namespace fs = std::filesystem;

std::string imagePath(const test::TumFolder& folder, const char* kind, std::size_t index,
                      const char* extension) {
  char name[64];
  const double t = kind[0] == 'r' ? folder.rgb_times[index] : folder.depth_times[index];
  std::snprintf(name, sizeof(name), "%s/%.6f%s", kind, t, extension);
  return (folder.dir / name).string();
}

void truncateFile(const std::string& path, double keep_fraction) {
  const auto size = fs::file_size(path);
  fs::resize_file(path, static_cast<std::uintmax_t>(static_cast<double>(size) * keep_fraction));
}

void overwriteBytes(const std::string& path, std::size_t offset, std::size_t count,
                    std::uint32_t seed) {
  std::fstream file(path, std::ios::in | std::ios::out | std::ios::binary);
  file.seekp(static_cast<std::streamoff>(offset));
  std::mt19937 rng(seed);
  for (std::size_t i = 0; i < count; ++i) file.put(static_cast<char>(rng() & 0xFF));
}

// Reads the folder expecting exactly one bad frame (index 1 of 3) whose message names `file`.
void expectOneSkip(const test::TumFolder& folder, const std::string& file,
                   const std::string& reason_fragment = "") {
  TumSource source(folder.dir.string(), test::smallTumConfig());
  source.open();
  const auto all = test::readAll(source);
  EXPECT_EQ(all.frames.size(), 2u);
  ASSERT_EQ(all.skip_messages.size(), 1u);
  EXPECT_NE(all.skip_messages[0].find(fs::path(file).filename().string()), std::string::npos)
      << all.skip_messages[0];
  if (!reason_fragment.empty()) {
    EXPECT_NE(all.skip_messages[0].find(reason_fragment), std::string::npos)
        << all.skip_messages[0];
  }
  EXPECT_EQ(source.stats().frames_skipped, 1u);
  EXPECT_EQ(source.stats().frames_read, 2u);
  EXPECT_EQ(source.stats().last_error, all.skip_messages[0]);
}

TEST(TumBadInput, MissingFolderIsASourceErrorNamingIt) {
  TumSource source("/nonexistent/slamd-tum", test::smallTumConfig());
  try {
    source.open();
    FAIL() << "no error";
  } catch (const SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/slamd-tum"), std::string::npos);
  }
}

TEST(TumBadInput, EmptyFolderIsASourceErrorNamingTheMissingList) {
  const test::ScopedTempDir dir("tum-empty");
  TumSource source(dir.string(), test::smallTumConfig());
  try {
    source.open();
    FAIL() << "no error";
  } catch (const SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("rgb.txt"), std::string::npos) << e.what();
  }
}

TEST(TumBadInput, ListWithOnlyCommentsIsASourceError) {
  const auto folder = test::writeTumFolder("tum-nolist", 2, false);
  std::ofstream(folder.dir / "rgb.txt") << "# nothing here\n";
  TumSource source(folder.dir.string(), test::smallTumConfig());
  EXPECT_THROW(source.open(), SourceError);
}

TEST(TumBadInput, NoPairWithinTheMaximumDifferenceIsASourceError) {
  const auto folder = test::writeTumFolder("tum-nopair", 2, false);
  TumSourceConfig config = test::smallTumConfig();
  config.max_difference_s = 0.001;  // colour and depth are 3 ms apart
  TumSource source(folder.dir.string(), config);
  EXPECT_THROW(source.open(), SourceError);
}

TEST(TumBadInput, MissingAssociationsFileIsASourceError) {
  const auto folder = test::writeTumFolder("tum-noassoc", 2, false);
  TumSourceConfig config = test::smallTumConfig();
  config.associations = "missing.txt";
  TumSource source(folder.dir.string(), config);
  EXPECT_THROW(source.open(), SourceError);
}

TEST(TumBadInput, TruncatedDepthPngIsSkippedAndCounted) {
  const auto folder = test::writeTumFolder("tum-trunc-depth", 3, false);
  const std::string path = imagePath(folder, "depth", 1, ".png");
  truncateFile(path, 0.5);
  expectOneSkip(folder, path);
}

TEST(TumBadInput, TruncatedColourPngIsSkippedAndCounted) {
  const auto folder = test::writeTumFolder("tum-trunc-png", 3, false);
  const std::string path = imagePath(folder, "rgb", 1, ".png");
  truncateFile(path, 0.6);
  expectOneSkip(folder, path);
}

TEST(TumBadInput, JpegWithGarbageBytesIsSkippedAndCounted) {
  const auto folder = test::writeTumFolder("tum-garbage-jpeg", 3, true);
  const std::string path = imagePath(folder, "rgb", 1, ".jpg");
  // Garbage in the entropy-coded data (after the headers): OpenCV alone would return an image.
  const auto size = fs::file_size(path);
  overwriteBytes(path, static_cast<std::size_t>(size / 2), 64, 42);
  expectOneSkip(folder, path, "corrupt JPEG");
}

TEST(TumBadInput, TruncatedJpegIsSkippedAndCounted) {
  const auto folder = test::writeTumFolder("tum-trunc-jpeg", 3, true);
  const std::string path = imagePath(folder, "rgb", 1, ".jpg");
  truncateFile(path, 0.7);
  expectOneSkip(folder, path, "corrupt JPEG");
}

TEST(TumBadInput, FileThatIsNotAnImageIsSkipped) {
  const auto folder = test::writeTumFolder("tum-notimage", 3, false);
  const std::string path = imagePath(folder, "depth", 1, ".png");
  std::ofstream(path, std::ios::trunc) << "this is not a PNG";
  expectOneSkip(folder, path);
}

TEST(TumBadInput, EmptyImageFileIsSkipped) {
  const auto folder = test::writeTumFolder("tum-emptyfile", 3, false);
  const std::string path = imagePath(folder, "rgb", 1, ".png");
  std::ofstream(path, std::ios::trunc).close();
  expectOneSkip(folder, path, "empty");
}

TEST(TumBadInput, ImagePathThatIsAFifoIsSkippedWithoutBlocking) {
  // Hostile-input issue, row 8: a FIFO in rgb.txt hung the capture thread (and SIGTERM) forever.
  const auto folder = test::writeTumFolder("tum-fifo", 3, false);
  const std::string path = imagePath(folder, "rgb", 1, ".png");
  fs::remove(path);
  ASSERT_EQ(mkfifo(path.c_str(), 0600), 0);
  expectOneSkip(folder, path, "not a regular file (a FIFO)");
}

TEST(TumBadInput, ImagePathThatIsADirectoryIsSkippedNamingIt) {
  // Row 8: a directory gave only "std::bad_alloc".
  const auto folder = test::writeTumFolder("tum-dir", 3, false);
  const std::string path = imagePath(folder, "depth", 1, ".png");
  fs::remove(path);
  fs::create_directory(path);
  expectOneSkip(folder, path, "not a regular file (a directory)");
}

TEST(TumBadInput, MissingImageFileIsSkipped) {
  const auto folder = test::writeTumFolder("tum-missingfile", 3, false);
  const std::string path = imagePath(folder, "depth", 1, ".png");
  fs::remove(path);
  expectOneSkip(folder, path, "cannot open");
}

TEST(TumBadInput, EightBitDepthImageIsSkippedAsWrongType) {
  const auto folder = test::writeTumFolder("tum-8bit", 3, false);
  const std::string path = imagePath(folder, "depth", 1, ".png");
  cv::imwrite(path, cv::Mat(48, 64, CV_8UC1, cv::Scalar(100)));
  expectOneSkip(folder, path, "CV_16UC1");
}

TEST(TumBadInput, DepthOfAnotherSizeThanColourIsSkipped) {
  const auto folder = test::writeTumFolder("tum-mismatch", 3, false);
  const std::string path = imagePath(folder, "depth", 1, ".png");
  cv::imwrite(path, test::makeDepthRaw(32, 24, 1));
  expectOneSkip(folder, path, "32x24");
}

TEST(TumBadInput, ImagesOfAnotherSizeThanTheConfiguredCameraAreSkipped) {
  const auto folder = test::writeTumFolder("tum-wrongsize", 3, false);
  cv::imwrite(imagePath(folder, "rgb", 1, ".png"), test::makeColor(32, 24, 1));
  cv::imwrite(imagePath(folder, "depth", 1, ".png"), test::makeDepthRaw(32, 24, 1));
  expectOneSkip(folder, imagePath(folder, "rgb", 1, ".png"), "camera.width");
}

TEST(TumBadInput, NonIncreasingTimestampsAreSkippedNamingTheListLine) {
  const auto folder = test::writeTumFolder("tum-order", 3, false);
  std::ofstream(folder.dir / "rgb.txt", std::ios::app)
      << "999.0 rgb/old.png\n";  // line 6: earlier than everything before it
  TumSource source(folder.dir.string(), test::smallTumConfig());
  source.open();
  const auto all = test::readAll(source);
  EXPECT_EQ(all.frames.size(), 3u);
  ASSERT_EQ(all.skip_messages.size(), 1u);
  EXPECT_NE(all.skip_messages[0].find("rgb.txt line 6"), std::string::npos) << all.skip_messages[0];
  EXPECT_EQ(source.stats().frames_skipped, 1u);
}

TEST(ImageIo, DecodesGreyPngAsBgrAndRejectsSixteenBitColour) {
  std::vector<std::uint8_t> bytes;
  cv::imencode(".png", cv::Mat(4, 5, CV_8UC1, cv::Scalar(7)), bytes);
  std::string error;
  const cv::Mat color = decodeColorImage(bytes.data(), bytes.size(), error);
  ASSERT_EQ(color.type(), CV_8UC3) << error;
  EXPECT_EQ(color.at<cv::Vec3b>(2, 3), cv::Vec3b(7, 7, 7));
  cv::imencode(".png", cv::Mat(4, 5, CV_16UC3, cv::Scalar(7)), bytes);
  EXPECT_TRUE(decodeColorImage(bytes.data(), bytes.size(), error).empty());
  EXPECT_NE(error.find("8-bit"), std::string::npos) << error;
}

TEST(ImageIo, StrictJpegMatchesOpenCvOnAGoodImage) {
  std::vector<std::uint8_t> bytes;
  const cv::Mat image = test::makeColor(64, 48, 7);
  cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, 95});
  std::string error;
  const cv::Mat ours = decodeColorImage(bytes.data(), bytes.size(), error);
  const cv::Mat opencv = cv::imdecode(bytes, cv::IMREAD_COLOR);
  ASSERT_FALSE(ours.empty()) << error;
  // The fast integer DCT: about a grey level on average, a few at most.
  EXPECT_LT(cv::norm(ours, opencv, cv::NORM_L1) / static_cast<double>(ours.total() * 3), 1.5);
  EXPECT_LE(cv::norm(ours, opencv, cv::NORM_INF), 8.0);
}

}  // namespace
}  // namespace slamd
