#include "slamd/capture/paced_source.hpp"

#include <gtest/gtest.h>

#include <thread>

#include "slamd/capture/preprocessed_source.hpp"

namespace slamd {
namespace {

// In-memory recorded source: `count` tiny frames `spacing_us` apart.
class FakeRecording : public FrameSource {
 public:
  FakeRecording(int count, Utime spacing_us) : count_(count), spacing_us_(spacing_us) {}
  void open() override { index_ = 0; }
  FrameRead next(std::chrono::milliseconds) override {
    if (index_ >= count_) return {FrameRead::Status::kEndOfStream, {}, {}};
    auto frame = std::make_shared<RgbdFrame>();
    frame->intrinsics = CameraIntrinsics{500, 500, 1.5, 1.5, 4, 4, DistortionModel::kNone, {}};
    frame->utime = 1'000'000 + index_ * spacing_us_;
    frame->sequence = index_++;
    frame->depth_m = cv::Mat(4, 4, CV_32FC1, cv::Scalar(0.1f));
    frame->depth_m.at<float>(1, 1) = 2.0f;
    ++stats_.frames_read;
    return {FrameRead::Status::kFrame, frame, {}};
  }
  void close() override {}
  FrameSourceStats stats() const override { return stats_; }
  std::string description() const override { return "fake"; }
  bool isLive() const override { return false; }

 private:
  int count_;
  Utime spacing_us_;
  int index_ = 0;
  FrameSourceStats stats_;
};

std::vector<std::pair<RgbdFramePtr, std::chrono::steady_clock::time_point>> drain(
    FrameSource& source) {
  std::vector<std::pair<RgbdFramePtr, std::chrono::steady_clock::time_point>> out;
  while (true) {
    FrameRead read = source.next(std::chrono::milliseconds(5));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status == FrameRead::Status::kFrame) {
      out.emplace_back(read.frame, std::chrono::steady_clock::now());
    }
  }
  return out;
}

TEST(PacedSource, AsFastAsPossibleDeliversEverythingAndIsNotLive) {
  PacedSource source(std::make_unique<FakeRecording>(50, 33'333), PacingConfig{});
  source.open();
  EXPECT_FALSE(source.isLive());
  EXPECT_EQ(drain(source).size(), 50u);
}

TEST(PacedSource, RealTimeNeverDeliversAFrameBeforeItsRecordedTime) {
  PacingConfig config;
  config.mode = PacingMode::kRealTime;
  config.max_lag_s = 10.0;  // nothing is late here
  PacedSource source(std::make_unique<FakeRecording>(10, 20'000), config);
  source.open();
  EXPECT_TRUE(source.isLive()) << "a real-time source must not be blocked by its consumer";
  const auto frames = drain(source);
  ASSERT_EQ(frames.size(), 10u);
  for (std::size_t i = 1; i < frames.size(); ++i) {
    const auto since_first = frames[i].second - frames[0].second;
    EXPECT_GE(since_first, std::chrono::microseconds(20'000 * static_cast<int>(i))) << i;
  }
}

TEST(PacedSource, TimeoutIsHonouredWhileTheNextFrameIsNotDue) {
  PacingConfig config;
  config.mode = PacingMode::kFixedRate;
  config.rate_hz = 1.0;  // one frame per second
  PacedSource source(std::make_unique<FakeRecording>(3, 1000), config);
  source.open();
  ASSERT_EQ(source.next(std::chrono::milliseconds(5)).status, FrameRead::Status::kFrame);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(source.next(std::chrono::milliseconds(5)).status, FrameRead::Status::kTimeout);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(900));
}

TEST(PacedSource, FramesReadTooLateAreDroppedAndCounted) {
  PacingConfig config;
  config.mode = PacingMode::kRealTime;
  config.max_lag_s = 0.005;
  PacedSource source(std::make_unique<FakeRecording>(20, 1000), config);  // 1 kHz recording
  source.open();
  ASSERT_EQ(source.next(std::chrono::milliseconds(5)).status, FrameRead::Status::kFrame);
  // Simulates a reader that stalls for 50 ms (not synchronisation): frames 1..~44 are then
  // more than 5 ms overdue.
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const auto frames = drain(source);
  const FrameSourceStats stats = source.stats();
  EXPECT_GT(stats.frames_dropped, 0u);
  EXPECT_EQ(stats.frames_read, frames.size() + 1);
  EXPECT_EQ(stats.frames_read + stats.frames_dropped, 20u) << "every frame delivered or counted";
}

TEST(PreprocessedSource, CleansDepthWithoutTouchingTheWrappedFrames) {
  DepthPreprocessorConfig config;
  config.range_gate = true;
  config.min_depth_m = 0.3;
  config.flying_pixels = false;
  PreprocessedSource source(std::make_unique<FakeRecording>(2, 1000), config);
  source.open();
  FrameRead read = source.next(std::chrono::milliseconds(5));
  ASSERT_EQ(read.status, FrameRead::Status::kFrame);
  EXPECT_TRUE(std::isnan(read.frame->depth_m.at<float>(0, 0)));
  EXPECT_FLOAT_EQ(read.frame->depth_m.at<float>(1, 1), 2.0f);
  EXPECT_EQ(source.timings().range_gate.count, 1u);
  EXPECT_EQ(source.timings().flying_pixels.count, 0u);
  EXPECT_EQ(source.timings().source_next.count, 1u);
}

}  // namespace
}  // namespace slamd
