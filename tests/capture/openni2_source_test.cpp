#include "slamd/capture/openni2_source.hpp"

#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

OpenNi2Config defaultConfig() {
  Config config;
  return OpenNi2Config::load(config);
}

TEST(OpenNi2Source, DummyDeviceDeliversRegisteredDepthAndColourFrames) {
  OpenNi2Source source(OpenNi2Source::Kind::kDevice, "Dummy", defaultConfig());
  source.open();
  EXPECT_TRUE(source.isLive());
  ASSERT_TRUE(source.intrinsics().has_value());
  // The DummyDevice offers 320x240 only: the 640x480 camera.* intrinsics are scaled.
  EXPECT_EQ(source.intrinsics()->width, 320);
  EXPECT_DOUBLE_EQ(source.intrinsics()->fx, 525.0 / 2);
  std::vector<RgbdFramePtr> frames;
  for (int i = 0; i < 200 && frames.size() < 5; ++i) {
    FrameRead read = source.next(std::chrono::milliseconds(1000));
    ASSERT_NE(read.status, FrameRead::Status::kEndOfStream);
    ASSERT_NE(read.status, FrameRead::Status::kSkipped) << read.message;
    if (read.status == FrameRead::Status::kFrame) frames.push_back(read.frame);
  }
  ASSERT_EQ(frames.size(), 5u);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const RgbdFrame& f = *frames[i];
    EXPECT_TRUE(f.validationError().empty()) << f.validationError();
    EXPECT_EQ(f.depth_m.size(), cv::Size(320, 240));
    EXPECT_EQ(f.color_bgr.size(), cv::Size(320, 240));
    if (i > 0) {
      EXPECT_GT(f.utime, frames[i - 1]->utime);
      EXPECT_GT(f.sequence, frames[i - 1]->sequence);
    }
    // The DummyDevice's depth pattern holds 2000 mm at the first pixel: 2 m.
    EXPECT_FLOAT_EQ(f.depth_m.at<float>(0, 0), 2.0f);
  }
  // Anchored to the wall clock: within a minute of now.
  EXPECT_LT(std::llabs(frames.back()->utime - wallClockUtime()), 60 * kUtimePerSecond);
  source.close();
  EXPECT_EQ(source.stats().frames_read, 5u);
}

TEST(OpenNi2Source, OniRecordedFromTheDummyDeviceOpensWithItsFrames) {
  const test::ScopedTempDir dir("oni");
  const std::string path = (dir / "dummy.oni").string();
  recordOni("Dummy", path, 12);
  ASSERT_TRUE(std::filesystem::exists(path));
  OpenNi2Source source(OpenNi2Source::Kind::kFile, path, defaultConfig());
  source.open();
  EXPECT_FALSE(source.isLive());
  EXPECT_EQ(source.description(), "oni:" + path);
  // The recorder may miss a frame at the start. It records every frame the driver delivers until
  // it is stopped, whether read or not: on a loaded machine the depth stream can run a few frames
  // ahead of colour, which the recording loop waits for (14 seen once under load).
  EXPECT_GE(source.recordedDepthFrames(), 11);
  EXPECT_LE(source.recordedDepthFrames(), 24);
  ASSERT_TRUE(source.intrinsics().has_value());
  EXPECT_EQ(source.intrinsics()->width, 320);
}

TEST(OpenNi2Source, DeviceThatStopsDeliveringIsReportedAndReopened) {
  OpenNi2Config config = defaultConfig();
  // The DummyDevice sends a frame every 33 ms: a 5 ms frame timeout makes every gap look like a
  // disconnect, which exercises detection, close and reopen on a real driver.
  config.frame_timeout_s = 0.005;
  config.reconnect_initial_s = 0.01;
  OpenNi2Source source(OpenNi2Source::Kind::kDevice, "Dummy", config);
  source.open();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (source.stats().reconnects < 2 && std::chrono::steady_clock::now() < deadline) {
    const FrameRead read = source.next(std::chrono::milliseconds(50));
    ASSERT_NE(read.status, FrameRead::Status::kEndOfStream) << "a device never ends";
  }
  const FrameSourceStats stats = source.stats();
  EXPECT_GE(stats.reconnects, 2u);
  EXPECT_NE(stats.last_error.find("disconnected"), std::string::npos) << stats.last_error;
  source.close();
}

TEST(OpenNi2Source, MissingOniFileIsASourceErrorNamingIt) {
  OpenNi2Source source(OpenNi2Source::Kind::kFile, "/nonexistent/recording.oni", defaultConfig());
  try {
    source.open();
    FAIL() << "no error";
  } catch (const SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/recording.oni"), std::string::npos);
  }
}

TEST(OpenNi2Source, RealDeviceDeliversFramesWhenAttached) {
  const auto devices = listOpenNi2Devices();
  if (devices.empty()) GTEST_SKIP() << "no OpenNI2 device attached; skipping";
  const std::string uri = devices.front().substr(0, devices.front().find(' '));
  OpenNi2Source source(OpenNi2Source::Kind::kDevice, uri, defaultConfig());
  source.open();
  int frames = 0;
  for (int i = 0; i < 100 && frames < 10; ++i) {
    if (source.next(std::chrono::milliseconds(1000)).status == FrameRead::Status::kFrame) ++frames;
  }
  EXPECT_EQ(frames, 10);
}

}  // namespace
}  // namespace slamd
