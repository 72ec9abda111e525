#include "slamd/sources/create_frame_source.hpp"

#include <gtest/gtest.h>

#include "slamd/capture/paced_source.hpp"
#include "test_data.hpp"
#include "tum_fixture.hpp"

namespace slamd {
namespace {

Config smallCamera() {
  Config config;
  config.set("camera.width", "64");
  config.set("camera.height", "48");
  config.set("camera.cx", "31.5");
  config.set("camera.cy", "23.5");
  return config;
}

TEST(CreateFrameSource, UnknownKindIsASourceErrorListingTheAcceptedOnes) {
  Config config;
  try {
    createFrameSource("kinect2:/dev/video0", config);
    FAIL() << "no error";
  } catch (const SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("tum:DIR"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("kinect2:/dev/video0"), std::string::npos);
  }
}

TEST(CreateFrameSource, MissingArgumentIsASourceError) {
  for (const char* spec : {"tum:", "oni:", "lcm:", "synthetic:", "tum"}) {
    Config config;
    EXPECT_THROW(createFrameSource(spec, config), SourceError) << spec;
  }
}

TEST(CreateFrameSource, TumFolderIsPreprocessedByDefaultAndNotLive) {
  const auto folder = test::writeTumFolder("factory-tum", 3, false);
  Config config = smallCamera();
  auto source = createFrameSource("tum:" + folder.dir.string(), config);
  ASSERT_NE(findPreprocessing(*source), nullptr);
  EXPECT_FALSE(source->isLive());
  EXPECT_NE(source->description().find("range-gate"), std::string::npos) << source->description();
  source->open();
  const auto all = test::readAll(*source);
  EXPECT_EQ(all.frames.size(), 3u);
  EXPECT_EQ(findPreprocessing(*source)->timings().preprocess.count, 3u);
}

TEST(CreateFrameSource, RealTimePacingMakesARecordingLive) {
  const auto folder = test::writeTumFolder("factory-paced", 2, false);
  Config config = smallCamera();
  config.set("capture.pacing.mode", "realtime");
  auto source = createFrameSource("tum:" + folder.dir.string(), config);
  EXPECT_NE(dynamic_cast<PacedSource*>(source.get()), nullptr);
  EXPECT_TRUE(source->isLive()) << "the consumer must never block a real-time source";
  EXPECT_NE(findPreprocessing(*source), nullptr);
}

TEST(CreateFrameSource, PreprocessingCanBeSwitchedOff) {
  const auto folder = test::writeTumFolder("factory-raw", 2, false);
  Config config = smallCamera();
  config.set("capture.preprocess.range_gate", "false");
  config.set("capture.preprocess.flying_pixels", "false");
  auto source = createFrameSource("tum:" + folder.dir.string(), config);
  EXPECT_EQ(findPreprocessing(*source), nullptr);
}

TEST(CreateFrameSource, BadConfigurationIsAConfigError) {
  Config config;
  config.set("capture.pacing.mode", "warp");
  EXPECT_THROW(createFrameSource("tum:/tmp", config), ConfigError);
}

#ifdef SLAMD_HAVE_OPENNI2
TEST(CreateFrameSource, OpenNi2DummyDeviceDeliversFrames) {
  Config config;
  auto source = createFrameSource("openni2:Dummy", config);
  EXPECT_TRUE(source->isLive());
  source->open();
  FrameRead read;
  for (int i = 0; i < 100 && read.status != FrameRead::Status::kFrame; ++i) {
    read = source->next(std::chrono::milliseconds(1000));
    ASSERT_NE(read.status, FrameRead::Status::kSkipped) << read.message;
  }
  ASSERT_EQ(read.status, FrameRead::Status::kFrame);
  EXPECT_EQ(read.frame->depth_m.size(), cv::Size(320, 240));
  source->close();
}

TEST(CreateFrameSource, RealTimePacingOfAnOniFileUsesOpenNisPlayer) {
  const auto folder = test::findDataset("oni");
  if (!folder) GTEST_SKIP() << test::missingDataMessage("oni");
  Config config;
  config.set("capture.pacing.mode", "realtime");
  auto source = createFrameSource("oni:" + (*folder / "kinect_room_12frames.oni").string(), config);
  EXPECT_EQ(dynamic_cast<PacedSource*>(source.get()), nullptr)
      << "slamd's pacer would have to read every frame it drops";
  EXPECT_TRUE(source->isLive());
  source->open();
  const auto all = test::readAll(*source);
  EXPECT_EQ(all.frames.size() + source->stats().frames_behind_schedule, 12u);
}
#endif

TEST(CreateFrameSource, SyntheticWorldWhenBuilt) {
#ifndef SLAMD_HAVE_SYNTH
  Config config;
  EXPECT_THROW(createFrameSource("synthetic:corridor", config), SourceError);
#else
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/synthetic.yaml");
  config.set("synthetic.frames", "3");
  auto source = createFrameSource("synthetic:corridor", config);
  source->open();
  const auto all = test::readAll(*source);
  ASSERT_EQ(all.frames.size(), 3u);
  EXPECT_TRUE(all.skip_messages.empty());
  ASSERT_TRUE(source->groundTruth().has_value());
  EXPECT_EQ(all.frames[0]->depth_m.size(), cv::Size(640, 480));
#endif
}

}  // namespace
}  // namespace slamd
