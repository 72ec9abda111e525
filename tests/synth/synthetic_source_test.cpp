#include "slamd/synth/synthetic_source.hpp"

#include <cstring>
#include <filesystem>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "slamd/capture/tum_source.hpp"
#include "slamd/synth/tum_writer.hpp"
#include "synth_test_support.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

bool sameBytes(const cv::Mat& a, const cv::Mat& b) {
  if (a.type() != b.type() || a.size() != b.size() || !a.isContinuous() || !b.isContinuous()) {
    return false;
  }
  return std::memcmp(a.data, b.data, a.total() * a.elemSize()) == 0;
}

TEST(SyntheticSource, TheSameSeedGivesTheSameBytes) {
  for (const std::string& scene : synth::sceneNames()) {
    const auto a = test::makeSyntheticSource(scene, {"synthetic.seed=7"});
    const auto b = test::makeSyntheticSource(scene, {"synthetic.seed=7"});
    const auto c = test::makeSyntheticSource(scene, {"synthetic.seed=8"});
    const RgbdFramePtr fa = a->renderFrame(12);
    const RgbdFramePtr fb = b->renderFrame(12);
    EXPECT_TRUE(sameBytes(fa->color_bgr, fb->color_bgr)) << scene;
    EXPECT_TRUE(sameBytes(fa->depth_m, fb->depth_m)) << scene;
    const RgbdFramePtr fc = c->renderFrame(12);
    EXPECT_FALSE(sameBytes(fa->color_bgr, fc->color_bgr)) << scene;
    EXPECT_FALSE(sameBytes(fa->depth_m, fc->depth_m)) << scene;
  }
}

TEST(SyntheticSource, AFrameDoesNotDependOnWhatWasRenderedBefore) {
  const auto a = test::makeSyntheticSource("room", {});
  const auto b = test::makeSyntheticSource("room", {});
  a->renderFrame(3);
  EXPECT_TRUE(sameBytes(a->renderFrame(40)->depth_m, b->renderFrame(40)->depth_m));
}

TEST(SyntheticSource, DeliversValidFramesThenEndOfStreamWithMatchingGroundTruth) {
  auto source = test::makeSyntheticSource("corridor_loop", {"synthetic.frames=5"});
  EXPECT_FALSE(source->isLive());
  ASSERT_TRUE(source->groundTruth().has_value());
  const Trajectory gt = *source->groundTruth();
  ASSERT_EQ(gt.size(), 5u);
  source->open();
  for (std::size_t i = 0; i < gt.size(); ++i) {
    const FrameRead read = source->next(std::chrono::milliseconds(100));
    ASSERT_EQ(read.status, FrameRead::Status::kFrame);
    EXPECT_EQ(read.frame->validationError(), "");
    EXPECT_EQ(read.frame->sequence, static_cast<std::int64_t>(i));
    EXPECT_EQ(read.frame->utime, secondsToUtime(gt[i].timestamp_s));
    EXPECT_FALSE(read.frame->gray.empty());
  }
  EXPECT_EQ(source->next(std::chrono::milliseconds(100)).status, FrameRead::Status::kEndOfStream);
  EXPECT_EQ(source->stats().frames_read, 5u);
  EXPECT_NE(source->description().find("corridor_loop"), std::string::npos);
}

TEST(SyntheticSource, EachSceneHasItsOwnDefaultTrajectory) {
  EXPECT_EQ(test::makeSyntheticSource("corridor", {})->motionKind(), synth::MotionKind::kZigzag);
  EXPECT_EQ(test::makeSyntheticSource("corridor_loop", {})->motionKind(), synth::MotionKind::kLoop);
  EXPECT_EQ(test::makeSyntheticSource("room", {})->motionKind(), synth::MotionKind::kRandom);
  EXPECT_EQ(test::makeSyntheticSource("room", {"synthetic.trajectory=robot"})->motionKind(),
            synth::MotionKind::kRobot);
}

TEST(SyntheticSource, AnUnknownSceneIsASourceErrorNamingIt) {
  Config config;
  try {
    createSyntheticSource("castle", config);
    FAIL() << "expected SourceError";
  } catch (const SourceError& error) {
    EXPECT_NE(std::string(error.what()).find("castle"), std::string::npos) << error.what();
  }
}

TEST(SyntheticSource, BadConfigurationNamesTheKeyAndValue) {
  Config config;
  config.applyOverride("synthetic.texture_density=1.5");
  try {
    createSyntheticSource("corridor", config);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& error) {
    EXPECT_NE(std::string(error.what()).find("synthetic.texture_density"), std::string::npos);
    EXPECT_NE(std::string(error.what()).find("1.5"), std::string::npos);
  }
  Config distorted;
  distorted.applyOverride("camera.distortion_model=plumb_bob");
  EXPECT_THROW(createSyntheticSource("room", distorted), ConfigError);
  Config ranges;
  ranges.applyOverride("synthetic.sensor.min_range_m=3");
  ranges.applyOverride("synthetic.sensor.max_range_m=2");
  EXPECT_THROW(createSyntheticSource("room", ranges), ConfigError);
}

TEST(SyntheticSource, MotionBlurAndExposureChangeTheColourOnly) {
  const auto plain = test::makeSyntheticSource("corridor", {"synthetic.sensor.color_noise_std=0"});
  const auto blurred = test::makeSyntheticSource(
      "corridor", {"synthetic.sensor.color_noise_std=0", "synthetic.sensor.motion_blur=true",
                   "synthetic.sensor.exposure_variation=0.2"});
  const RgbdFramePtr a = plain->renderFrame(30);
  const RgbdFramePtr b = blurred->renderFrame(30);
  EXPECT_TRUE(sameBytes(a->depth_m, b->depth_m));
  EXPECT_GT(cv::norm(a->color_bgr, b->color_bgr, cv::NORM_L1) / a->color_bgr.total(), 1.0);
}

TEST(SyntheticSource, MotionBlurIsCentredOnTheFrameTimestamp) {
  // An exposure of two frame periods spans frames 29..31 when centred on frame 30's timestamp, so
  // the blurred frame is as far from frame 29's sharp render as from frame 31's. An exposure that
  // ended at the timestamp (frames 28..30) would sit much closer to frame 29.
  const auto sharp = test::makeSyntheticSource("corridor", {"synthetic.sensor.color_noise_std=0"});
  const auto blurred = test::makeSyntheticSource(
      "corridor",
      {"synthetic.sensor.color_noise_std=0", "synthetic.sensor.motion_blur=true",
       "synthetic.sensor.exposure_time_s=0.0666667", "synthetic.sensor.blur_samples=9"});
  const RgbdFramePtr before = sharp->renderFrame(29);
  const RgbdFramePtr after = sharp->renderFrame(31);
  const RgbdFramePtr frame = blurred->renderFrame(30);
  const double to_before = cv::norm(frame->color_bgr, before->color_bgr, cv::NORM_L1);
  const double to_after = cv::norm(frame->color_bgr, after->color_bgr, cv::NORM_L1);
  EXPECT_GT(to_before, 0.0);
  EXPECT_NEAR(to_before / to_after, 1.0, 0.15) << to_before << " vs " << to_after;
}

TEST(SyntheticSource, ABlackoutCoversExactlyTheFramesInItsInterval) {
  // At 30 Hz, [1.0 s, 1.5 s) covers frames 30 to 44.
  const auto source = test::makeSyntheticSource(
      "room", {"synthetic.blackout_start_s=1.0", "synthetic.blackout_duration_s=0.5"});
  for (const int index : {29, 30, 44, 45}) {
    const RgbdFramePtr frame = source->renderFrame(index);
    const bool covered = index >= 30 && index <= 44;
    EXPECT_EQ(cv::countNonZero(frame->gray) == 0, covered) << "frame " << index;
    EXPECT_EQ(cv::countNonZero(frame->depth_m == frame->depth_m) == 0, covered)  // NaN != NaN
        << "frame " << index;
  }
  EXPECT_EQ(source->groundTruth()->size(), static_cast<std::size_t>(source->frameCount()));
}

// Writes five corridor frames as a TUM folder in `format` and reads them back with TumSource.
void expectTumFolderReadsBackIdentically(TumImageFormat format) {
  const test::ScopedTempDir dir("synth-tum");
  auto source = test::makeSyntheticSource("corridor", {"synthetic.frames=5"});
  const Trajectory gt = *source->groundTruth();
  std::vector<RgbdFramePtr> written;
  {
    TumSequenceWriter writer(dir.string(), "test", 5000.0, format);
    writer.open();
    source->open();
    for (FrameRead read = source->next(std::chrono::milliseconds(100));
         read.status == FrameRead::Status::kFrame;
         read = source->next(std::chrono::milliseconds(100))) {
      writer.write(*read.frame);
      written.push_back(read.frame);
    }
    writer.finish(gt);
  }
  ASSERT_EQ(written.size(), 5u);
  // The images are in the format asked for (TumSource reads either).
  for (const auto& [list, extension] :
       {std::pair{"rgb", format == TumImageFormat::kPng ? ".png" : ".ppm"},
        std::pair{"depth", format == TumImageFormat::kPng ? ".png" : ".pgm"}}) {
    int images = 0;
    for (const auto& entry : std::filesystem::directory_iterator(dir.path() / list)) {
      EXPECT_EQ(entry.path().extension().string(), extension) << entry.path();
      ++images;
    }
    EXPECT_EQ(images, 5) << list;
  }

  Config config;
  TumSource tum(dir.string(), TumSourceConfig::load(config));
  tum.open();
  for (std::size_t i = 0; i < written.size(); ++i) {
    const FrameRead read = tum.next(std::chrono::milliseconds(1000));
    ASSERT_EQ(read.status, FrameRead::Status::kFrame) << read.message;
    EXPECT_EQ(read.frame->utime, written[i]->utime);
    EXPECT_TRUE(sameBytes(read.frame->color_bgr, written[i]->color_bgr)) << "frame " << i;
    // Depth is exact at the file's 1/5000 m quantisation (NaN where nothing was measured).
    const cv::Mat expected =
        depthRawToMeters(depthMetersToRaw(written[i]->depth_m, 5000.0), 5000.0);
    EXPECT_TRUE(sameBytes(read.frame->depth_m, expected)) << "frame " << i;
    const double worst_error_m = [&] {
      double worst = 0.0;
      for (int r = 0; r < expected.rows; ++r) {
        for (int c = 0; c < expected.cols; ++c) {
          const double z = written[i]->depth_m.at<float>(r, c);
          const double read_z = read.frame->depth_m.at<float>(r, c);
          if (std::isfinite(z)) worst = std::max(worst, std::abs(read_z - z));
        }
      }
      return worst;
    }();
    EXPECT_LE(worst_error_m, 0.5 / 5000.0 + 1e-6);
  }
  EXPECT_EQ(tum.next(std::chrono::milliseconds(100)).status, FrameRead::Status::kEndOfStream);
  ASSERT_TRUE(tum.groundTruth().has_value());
  const Trajectory read_gt = *tum.groundTruth();
  ASSERT_EQ(read_gt.size(), gt.size());
  for (std::size_t i = 0; i < gt.size(); ++i) {
    EXPECT_EQ(secondsToUtime(read_gt[i].timestamp_s), secondsToUtime(gt[i].timestamp_s));
    EXPECT_LT((read_gt[i].T_world_camera.translation() - gt[i].T_world_camera.translation()).norm(),
              2e-9);
    EXPECT_LT(rotationAngleRad(read_gt[i].T_world_camera.linear().transpose() *
                               gt[i].T_world_camera.linear()),
              1e-8);
  }
}

TEST(SyntheticSource, AWrittenSequenceReadBackByTheTumSourceGivesIdenticalFramesAndPoses) {
  expectTumFolderReadsBackIdentically(TumImageFormat::kPng);
}

TEST(SyntheticSource, AnUncompressedSequenceReadsBackAsIdenticallyAsPng) {
  expectTumFolderReadsBackIdentically(TumImageFormat::kUncompressed);
}

TEST(TumSequenceWriter, WritesTimestampsAsTheBenchmarkDoes) {
  EXPECT_EQ(formatTumTimestamp(1305031102175304), "1305031102.175304");
  EXPECT_EQ(formatTumTimestamp(1600000000033333), "1600000000.033333");
  EXPECT_EQ(formatTumTimestamp(5), "0.000005");
}

TEST(TumSequenceWriter, ADepthMapTakenAtItsOwnTimeIsWrittenAndReadBackAtThatTime) {
  // A Kinect's depth and colour images are taken up to half a frame apart (fr1/xyz: 0-20 ms);
  // copying such a sequence must not move its depth to the colour's time.
  const test::ScopedTempDir dir("synth-tum-depth-time");
  auto source = test::makeSyntheticSource("corridor", {"synthetic.frames=3"});
  std::vector<std::pair<Utime, Utime>> written_utimes;  // colour, depth
  {
    TumSequenceWriter writer(dir.string(), "test", 5000.0, TumImageFormat::kUncompressed);
    writer.open();
    source->open();
    for (FrameRead read = source->next(std::chrono::milliseconds(100));
         read.status == FrameRead::Status::kFrame;
         read = source->next(std::chrono::milliseconds(100))) {
      RgbdFrame frame = *read.frame;
      frame.depth_utime = frame.utime - 12345;
      writer.write(frame);
      written_utimes.emplace_back(frame.utime, frame.depth_utime);
    }
    writer.finish({});
  }
  ASSERT_EQ(written_utimes.size(), 3u);
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "depth" /
                                      (formatTumTimestamp(written_utimes[0].second) + ".pgm")));

  Config config;
  TumSource tum(dir.string(), TumSourceConfig::load(config));
  tum.open();
  for (const auto& [colour_utime, depth_utime] : written_utimes) {
    const FrameRead read = tum.next(std::chrono::milliseconds(1000));
    ASSERT_EQ(read.status, FrameRead::Status::kFrame) << read.message;
    EXPECT_EQ(read.frame->utime, colour_utime);
    EXPECT_EQ(read.frame->depth_utime, depth_utime);
  }
}

TEST(TumSequenceWriter, ParsesTheImageFormatsTheToolsOffer) {
  EXPECT_EQ(parseTumImageFormat("png"), TumImageFormat::kPng);
  EXPECT_EQ(parseTumImageFormat("uncompressed"), TumImageFormat::kUncompressed);
  EXPECT_FALSE(parseTumImageFormat("ppm").has_value());
  EXPECT_FALSE(parseTumImageFormat("").has_value());
}

TEST(TumSequenceWriter, AnUnwritableFolderIsAnErrorNamingIt) {
  TumSequenceWriter writer("/proc/slamd-synth-cannot-write", "test");
  try {
    writer.open();
    FAIL() << "expected std::runtime_error";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("/proc/slamd-synth-cannot-write"), std::string::npos);
  }
}

}  // namespace
}  // namespace slamd
