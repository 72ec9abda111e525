// slamd-play as a converter: a TUM folder written with --write-tum --images uncompressed plays
// back the same frames (pixels, colour and depth times) as the folder it was made from. make soak
// plays fr1/xyz this way, so that decoding PNGs is not charged to slamd.

#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "slamd/capture/tum_source.hpp"
#include "test_data.hpp"
#include "tum_fixture.hpp"

namespace slamd {
namespace {

int exitCode(const std::string& command) {
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(SlamdPlay, AnUncompressedCopyOfATumFolderReadsBackAsTheSameFrames) {
#ifndef SLAMD_PLAY_PATH
  GTEST_SKIP() << "slamd-play is not built in this tree; skipping";
#elif !defined(SLAMD_HAVE_SYNTH)
  GTEST_SKIP() << "--write-tum needs the synth area, not built in this tree; skipping";
#else
  constexpr int kFrames = 4;
  const auto original = test::writeTumFolder("play-copy-original", kFrames, false);
  const test::ScopedTempDir dir("play-copy");
  const std::filesystem::path copy = dir / "copy";
  const std::string camera =
      " --set camera.width=64 --set camera.height=48 --set camera.cx=31.5 --set camera.cy=23.5";
  const std::string command = std::string(SLAMD_PLAY_PATH) +
                              " --source tum:" + original.dir.string() + camera + " --write-tum " +
                              copy.string() +
                              " --images uncompressed --set capture.preprocess.range_gate=false"
                              " --set capture.preprocess.flying_pixels=false > " +
                              (dir / "play.log").string() + " 2>&1";
  ASSERT_EQ(exitCode(command), 0) << "see " << dir / "play.log";
  char first_depth[64];
  std::snprintf(first_depth, sizeof(first_depth), "%.6f.pgm", original.depth_times[0]);
  EXPECT_TRUE(std::filesystem::exists(copy / "depth" / first_depth)) << "written at its own time";

  TumSource from_original(original.dir.string(), test::smallTumConfig());
  TumSource from_copy(copy.string(), test::smallTumConfig());
  from_original.open();
  from_copy.open();
  for (int i = 0; i < kFrames; ++i) {
    const FrameRead a = from_original.next(std::chrono::milliseconds(1000));
    const FrameRead b = from_copy.next(std::chrono::milliseconds(1000));
    ASSERT_EQ(a.status, FrameRead::Status::kFrame) << a.message;
    ASSERT_EQ(b.status, FrameRead::Status::kFrame) << b.message;
    EXPECT_EQ(b.frame->utime, a.frame->utime) << "frame " << i;
    EXPECT_EQ(b.frame->depth_utime, a.frame->depth_utime) << "frame " << i;
    EXPECT_EQ(cv::norm(a.frame->color_bgr, b.frame->color_bgr, cv::NORM_INF), 0.0) << i;
    // Depth equal where measured, and missing (NaN) where it was missing.
    int missing = 0;
    int different = 0;
    for (int r = 0; r < a.frame->depth_m.rows; ++r) {
      for (int c = 0; c < a.frame->depth_m.cols; ++c) {
        const float za = a.frame->depth_m.at<float>(r, c);
        const float zb = b.frame->depth_m.at<float>(r, c);
        if (std::isnan(za)) ++missing;
        if (std::isnan(za) != std::isnan(zb) || (!std::isnan(za) && za != zb)) ++different;
      }
    }
    EXPECT_EQ(missing, 1) << "frame " << i << ": the fixture's one hole";
    EXPECT_EQ(different, 0) << "frame " << i;
  }
  EXPECT_EQ(from_copy.next(std::chrono::milliseconds(100)).status, FrameRead::Status::kEndOfStream);
#endif
}

TEST(SlamdPlay, AnUnknownImageFormatIsAUsageError) {
#ifndef SLAMD_PLAY_PATH
  GTEST_SKIP() << "slamd-play is not built in this tree; skipping";
#else
  const auto original = test::writeTumFolder("play-bad-format", 1, false);
  const test::ScopedTempDir dir("play-bad-format-out");
  const std::string command = std::string(SLAMD_PLAY_PATH) +
                              " --source tum:" + original.dir.string() + " --write-tum " +
                              (dir / "copy").string() + " --images jpeg > /dev/null 2>&1";
  EXPECT_EQ(exitCode(command), 2);
#endif
}

}  // namespace
}  // namespace slamd
