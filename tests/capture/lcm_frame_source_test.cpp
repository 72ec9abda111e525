#include "slamd/comms/lcm_frame_source.hpp"

#include <chrono>
#include <cmath>
#include <thread>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>

#include "slamd/comms/lcm_frame_publisher.hpp"
#include "slamd/comms/message_codec.hpp"
#include "tum_fixture.hpp"

namespace slamd {
namespace {

constexpr const char* kChannel = "SLAMD_TEST_FRAMES";

RgbdFramePtr makeFrame(int index, int width = 64, int height = 48) {
  auto frame = std::make_shared<RgbdFrame>();
  frame->utime = 1'700'000'000'000'000 + index * 33'333;
  frame->sequence = index;
  frame->intrinsics =
      CameraIntrinsics{525.0, 525.0, 31.5, 23.5, width, height, DistortionModel::kNone, {}};
  frame->color_bgr = test::makeColor(width, height, 42u + static_cast<unsigned>(index));
  frame->depth_m = depthRawToMeters(test::makeDepthRaw(width, height, index), 5000.0);
  ensureGray(*frame);
  return frame;
}

struct MemqFixture {
  std::shared_ptr<lcm::LCM> lcm = std::make_shared<lcm::LCM>("memq://");
  LcmFrameSourceConfig source_config() {
    Config config;
    config.set("camera.width", "64");
    config.set("camera.height", "48");
    config.set("camera.cx", "31.5");
    config.set("camera.cy", "23.5");
    // Tests publish everything before reading: room for all, so nothing is dropped.
    config.set("capture.lcm.queue_capacity", "64");
    return LcmFrameSourceConfig::load(config);
  }
};

// Reads until `count` frames or skips have come, or the deadline passes.
test::ReadAll readCount(FrameSource& source, std::size_t count) {
  test::ReadAll out;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (out.frames.size() + out.skip_messages.size() < count &&
         std::chrono::steady_clock::now() < deadline) {
    FrameRead read = source.next(std::chrono::milliseconds(100));
    if (read.status == FrameRead::Status::kFrame) out.frames.push_back(read.frame);
    if (read.status == FrameRead::Status::kSkipped) out.skip_messages.push_back(read.message);
  }
  return out;
}

void publishRaw(lcm::LCM& lcm, const std::vector<std::uint8_t>& bytes) {
  ASSERT_EQ(lcm.publish(kChannel, bytes.data(), static_cast<unsigned int>(bytes.size())), 0);
}

TEST(LcmFrameSource, RgbdFramesRoundTripLosslesslyWithPngAndZlibDepth) {
  for (const char* depth : {"png", "zlib"}) {
    MemqFixture memq;
    LcmFrameSource source(memq.lcm, kChannel, memq.source_config());
    source.open();
    Config config;
    config.set("capture.publish.channel", kChannel);
    config.set("capture.publish.color", "png");
    config.set("capture.publish.depth", depth);
    config.set("capture.publish.depth_scale", "5000");
    LcmFramePublisher publisher(*memq.lcm, LcmFramePublisherConfig::load(config));
    std::vector<RgbdFramePtr> sent;
    for (int i = 0; i < 5; ++i) {
      sent.push_back(makeFrame(i));
      ASSERT_TRUE(publisher.publish(*sent.back()));
    }
    const auto received = readCount(source, 5);
    ASSERT_EQ(received.frames.size(), 5u) << depth;
    for (std::size_t i = 0; i < 5; ++i) {
      const RgbdFrame& a = *sent[i];
      const RgbdFrame& b = *received.frames[i];
      EXPECT_EQ(b.utime, a.utime);
      EXPECT_EQ(b.sequence, a.sequence);
      EXPECT_EQ(b.intrinsics, a.intrinsics);
      EXPECT_EQ(cv::norm(a.color_bgr, b.color_bgr, cv::NORM_INF), 0.0);
      EXPECT_EQ(cv::norm(depthMetersToRaw(a.depth_m, 5000.0), depthMetersToRaw(b.depth_m, 5000.0),
                         cv::NORM_INF),
                0.0);
      EXPECT_TRUE(std::isnan(b.depth_m.at<float>(0, 0)));
    }
    EXPECT_EQ(source.stats().frames_read, 5u);
    EXPECT_EQ(source.stats().frames_skipped, 0u);
    EXPECT_EQ(publisher.published(), 5u);
  }
}

TEST(LcmFrameSource, KinectFramesRoundTripWithIntrinsicsFromConfig) {
  MemqFixture memq;
  LcmFrameSource source(memq.lcm, kChannel, memq.source_config());
  source.open();
  Config config;
  config.set("capture.publish.channel", kChannel);
  config.set("capture.publish.format", "kinect");
  config.set("capture.publish.color", "rgb8");
  config.set("capture.publish.depth", "zlib");
  LcmFramePublisher publisher(*memq.lcm, LcmFramePublisherConfig::load(config));
  const RgbdFramePtr frame = makeFrame(3);
  ASSERT_TRUE(publisher.publish(*frame));
  const auto received = readCount(source, 1);
  ASSERT_EQ(received.frames.size(), 1u);
  const RgbdFrame& b = *received.frames[0];
  EXPECT_EQ(b.utime, frame->utime);
  EXPECT_EQ(b.intrinsics, frame->intrinsics);
  EXPECT_EQ(cv::norm(frame->color_bgr, b.color_bgr, cv::NORM_INF), 0.0);
  // Kinect depth is millimetres: equal to the millimetre rounding of what was sent.
  EXPECT_EQ(cv::norm(depthMetersToRaw(frame->depth_m, 1000.0), depthMetersToRaw(b.depth_m, 1000.0),
                     cv::NORM_INF),
            0.0);
}

TEST(LcmFrameSource, MalformedMessagesAreSkippedCountedAndNamed) {
  MemqFixture memq;
  LcmFrameSource source(memq.lcm, kChannel, memq.source_config());
  source.open();
  FrameEncodeOptions options;
  options.depth_scale = 5000.0;

  // 1. Garbage bytes.
  publishRaw(*memq.lcm, {1, 2, 3, 4, 5, 6, 7, 8, 9, 10});
  // 2. A truncated slamd.rgbd_frame_t.
  auto bytes = encodeMessage(encodeRgbdFrame(*makeFrame(1), options));
  bytes.resize(bytes.size() / 2);
  publishRaw(*memq.lcm, bytes);
  // 3. JPEG colour with garbage in the middle.
  auto message = encodeRgbdFrame(*makeFrame(2), options);
  for (std::size_t i = message.color_data.size() / 2; i < message.color_data.size() / 2 + 64; ++i) {
    message.color_data[i] = static_cast<std::uint8_t>(i * 7);
  }
  publishRaw(*memq.lcm, encodeMessage(message));
  // 4. A kinect frame with a colour format slamd does not read.
  auto kinect = encodeKinectFrame(*makeFrame(3), true, true);
  kinect.image.image_data_format = kinect::image_msg_t::VIDEO_BAYER;
  publishRaw(*memq.lcm, encodeMessage(kinect));
  // 5. A good frame, then 6. one whose timestamp does not increase, then 7. a good one.
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(5), options)));
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(4), options)));
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(6), options)));

  const auto received = readCount(source, 7);
  ASSERT_EQ(received.skip_messages.size(), 5u);
  ASSERT_EQ(received.frames.size(), 2u);
  EXPECT_EQ(received.frames[0]->sequence, 5);
  EXPECT_EQ(received.frames[1]->sequence, 6);
  for (const auto& m : received.skip_messages) {
    EXPECT_NE(m.find(kChannel), std::string::npos) << m;
  }
  EXPECT_NE(received.skip_messages[0].find("LCM message #1"), std::string::npos);
  EXPECT_NE(received.skip_messages[0].find("are not slamd.rgbd_frame_t or kinect.frame_msg_t"),
            std::string::npos)
      << received.skip_messages[0];
  EXPECT_NE(received.skip_messages[1].find("truncated"), std::string::npos)
      << received.skip_messages[1];
  EXPECT_NE(received.skip_messages[2].find("corrupt"), std::string::npos)
      << received.skip_messages[2];
  EXPECT_NE(received.skip_messages[3].find("colour format 1"), std::string::npos)
      << received.skip_messages[3];
  EXPECT_NE(received.skip_messages[4].find("does not increase"), std::string::npos)
      << received.skip_messages[4];
  EXPECT_EQ(source.stats().frames_skipped, 5u);
  EXPECT_EQ(source.stats().frames_read, 2u);
}

// Hostile-input issue, row 4: one frame stamped far in the future (or a bit-flipped utime) made
// every later frame "not increase", and poses never resumed.
TEST(LcmFrameSource, OneFrameFarFromTheStreamsClockIsRejectedAndTheStreamGoesOn) {
  MemqFixture memq;
  LcmFrameSource source(memq.lcm, kChannel, memq.source_config());
  source.open();
  FrameEncodeOptions options;
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(0), options)));
  RgbdFrame future = *makeFrame(1);
  future.utime += 3600LL * 1'000'000;  // an hour ahead
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(future, options)));
  RgbdFrame flipped = *makeFrame(2);
  flipped.utime ^= 1LL << 52;  // one flipped bit
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(flipped, options)));
  for (int i = 3; i < 6; ++i) {
    publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(i), options)));
  }
  const auto received = readCount(source, 6);
  ASSERT_EQ(received.frames.size(), 4u);
  EXPECT_EQ(received.frames.back()->sequence, 5);
  ASSERT_EQ(received.skip_messages.size(), 2u);
  for (const auto& message : received.skip_messages) {
    EXPECT_NE(message.find("off the stream's clock"), std::string::npos) << message;
  }
  EXPECT_EQ(source.stats().clock_reanchors, 0u);
}

TEST(LcmFrameSource, AClockThatReallyJumpsIsReanchoredAfterAgreeingFrames) {
  MemqFixture memq;
  LcmFrameSource source(memq.lcm, kChannel, memq.source_config());
  source.open();
  FrameEncodeOptions options;
  for (int i = 0; i < 3; ++i) {
    publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(i), options)));
  }
  // The camera restarted: its clock now reads 100 s earlier, consistently.
  for (int i = 3; i < 10; ++i) {
    RgbdFrame frame = *makeFrame(i);
    frame.utime -= 100LL * 1'000'000;
    publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(frame, options)));
  }
  const auto received = readCount(source, 10);
  // 4 rejected, the 5th agreeing frame re-anchors the stream and is delivered, as are the rest.
  EXPECT_EQ(received.skip_messages.size(), 4u);
  ASSERT_EQ(received.frames.size(), 6u);
  EXPECT_EQ(received.frames[3]->sequence, 7);
  EXPECT_EQ(source.stats().clock_reanchors, 1u);
}

// A pause in delivery is not a clock jump: frames that arrive late but in order (a camera that
// stalled, a log recorded while its producer was held up and replayed with the same gaps) are
// accepted. Before, every frame after a pause longer than capture.lcm.max_time_jump_s was
// rejected until the clock re-anchored, and a replayed log lost frames.
TEST(LcmFrameSource, FramesArrivingLateButInOrderAreAPauseNotAJump) {
  MemqFixture memq;
  LcmFrameSourceConfig config = memq.source_config();
  config.max_time_jump_s = 0.1;
  LcmFrameSource source(memq.lcm, kChannel, config);
  source.open();
  FrameEncodeOptions options;
  for (int i = 0; i < 6; ++i) {
    if (i == 3) std::this_thread::sleep_for(std::chrono::milliseconds(400));  // 4x the tolerance
    publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(i), options)));
  }
  const auto received = readCount(source, 6);
  EXPECT_TRUE(received.skip_messages.empty())
      << (received.skip_messages.empty() ? "" : received.skip_messages[0]);
  ASSERT_EQ(received.frames.size(), 6u);
  EXPECT_EQ(received.frames.back()->sequence, 5);
  EXPECT_EQ(source.stats().clock_reanchors, 0u);
}

TEST(LcmFrameSource, FormatOptionRejectsTheOtherType) {
  MemqFixture memq;
  LcmFrameSourceConfig config = memq.source_config();
  config.format = LcmFrameFormat::kKinectFrame;
  LcmFrameSource source(memq.lcm, kChannel, config);
  source.open();
  FrameEncodeOptions options;
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(1), options)));
  const auto received = readCount(source, 1);
  ASSERT_EQ(received.skip_messages.size(), 1u);
  EXPECT_NE(received.skip_messages[0].find("are not kinect.frame_msg_t"), std::string::npos);
}

TEST(LcmFrameSource, ASlowReaderLosesTheOldestMessagesAndCountsThem) {
  MemqFixture memq;
  LcmFrameSourceConfig config = memq.source_config();
  config.queue_capacity = 2;
  LcmFrameSource source(memq.lcm, kChannel, config);
  source.open();
  FrameEncodeOptions options;
  for (int i = 0; i < 10; ++i) {
    publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(i), options)));
  }
  // Wait (with a deadline) until the receive thread has taken all ten, without reading any.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (source.messagesReceived() < 10 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::yield();
  }
  ASSERT_EQ(source.messagesReceived(), 10u);
  const auto received = readCount(source, 2);
  ASSERT_EQ(received.frames.size(), 2u);
  EXPECT_EQ(received.frames[0]->sequence, 8) << "the newest messages are kept";
  EXPECT_EQ(received.frames[1]->sequence, 9);
  EXPECT_EQ(source.next(std::chrono::milliseconds(10)).status, FrameRead::Status::kTimeout);
  EXPECT_EQ(source.stats().frames_dropped, 8u);
}

TEST(LcmFrameSource, IdleEndFinishesAReplayedStream) {
  MemqFixture memq;
  LcmFrameSourceConfig config = memq.source_config();
  config.idle_end_s = 0.2;
  LcmFrameSource source(memq.lcm, kChannel, config);
  source.open();
  EXPECT_EQ(source.next(std::chrono::milliseconds(300)).status, FrameRead::Status::kTimeout)
      << "nothing received yet: keep waiting";
  FrameEncodeOptions options;
  publishRaw(*memq.lcm, encodeMessage(encodeRgbdFrame(*makeFrame(1), options)));
  ASSERT_EQ(readCount(source, 1).frames.size(), 1u);
  FrameRead read;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  do {
    read = source.next(std::chrono::milliseconds(100));
  } while (read.status == FrameRead::Status::kTimeout &&
           std::chrono::steady_clock::now() < deadline);
  EXPECT_EQ(read.status, FrameRead::Status::kEndOfStream);
}

TEST(LcmFrameSource, BadUrlIsASourceError) {
  LcmFrameSourceConfig config;
  config.url = "nonsense://nowhere";
  LcmFrameSource source(kChannel, config);
  EXPECT_THROW(source.open(), SourceError);
}

}  // namespace
}  // namespace slamd
