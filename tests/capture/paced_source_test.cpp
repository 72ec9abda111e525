#include "slamd/capture/paced_source.hpp"

#include <thread>

#include <gtest/gtest.h>

#include "slamd/capture/preprocessed_source.hpp"

namespace slamd {
namespace {

// In-memory recorded source: `count` tiny frames `spacing_us` apart. With `can_pass_over` it
// tells its timestamps ahead and passes over frames unread, as datasets and synthetic worlds do;
// `read_time` makes every read take that long (a slow decoder or renderer).
class FakeRecording : public FrameSource {
 public:
  FakeRecording(int count, Utime spacing_us, bool can_pass_over = false,
                std::chrono::milliseconds read_time = std::chrono::milliseconds(0))
      : count_(count),
        spacing_us_(spacing_us),
        can_pass_over_(can_pass_over),
        read_time_(read_time) {}
  void open() override { index_ = 0; }
  std::optional<Utime> upcomingUtime(std::size_t ahead) const override {
    if (!can_pass_over_ || index_ + static_cast<int>(ahead) >= count_) return std::nullopt;
    return utimeOf(index_ + static_cast<int>(ahead));
  }
  bool dropUpcoming() override {
    if (!upcomingUtime(0)) return false;
    ++index_;
    ++stats_.frames_dropped;
    ++stats_.frames_behind_schedule;
    return true;
  }
  FrameRead next(std::chrono::milliseconds) override {
    if (index_ >= count_) return {FrameRead::Status::kEndOfStream, {}, {}};
    // Simulated work (decoding or rendering), not synchronisation.
    if (read_time_.count() > 0) std::this_thread::sleep_for(read_time_);
    auto frame = std::make_shared<RgbdFrame>();
    frame->intrinsics = CameraIntrinsics{500, 500, 1.5, 1.5, 4, 4, DistortionModel::kNone, {}};
    frame->utime = utimeOf(index_);
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
  Utime utimeOf(int index) const { return 1'000'000 + index * spacing_us_; }

  int count_;
  Utime spacing_us_;
  bool can_pass_over_;
  std::chrono::milliseconds read_time_;
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

TEST(PacedSource, BehindScheduleItPassesOverFramesUnreadAndDeliversEveryFrameItReads) {
  PacingConfig config;
  config.mode = PacingMode::kRealTime;
  config.max_lag_s = 0.005;
  PacedSource source(std::make_unique<FakeRecording>(100, 1000, true), config);  // 1 kHz
  source.open();
  ASSERT_EQ(source.next(std::chrono::milliseconds(5)).status, FrameRead::Status::kFrame);
  // Simulates a reader that stalls for 50 ms (not synchronisation).
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const auto frames = drain(source);
  ASSERT_FALSE(frames.empty());
  // The first frame after the stall is the newest one due: about 50 frames were passed over.
  EXPECT_GE(frames.front().first->sequence, 45);
  const FrameSourceStats stats = source.stats();
  EXPECT_GE(stats.frames_behind_schedule, 44u);
  EXPECT_EQ(stats.frames_dropped, stats.frames_behind_schedule);
  // Nothing read was thrown away: every frame is delivered or passed over unread.
  EXPECT_EQ(stats.frames_read, frames.size() + 1);
  EXPECT_EQ(stats.frames_read + stats.frames_dropped, 100u);
}

TEST(PacedSource, ASlowSourceDeliversTheNewestDueFrameInsteadOfFallingFurtherBehind) {
  // Frames 10 ms apart whose reading takes 25 ms (a renderer slower than real time): the old
  // player read each frame, found it late and dropped it, so it never caught up. Now each read
  // starts at the newest frame due, so about every third frame comes out (the old player
  // delivered none of them).
  PacingConfig config;
  config.mode = PacingMode::kRealTime;
  config.max_lag_s = 0.005;
  PacedSource source(
      std::make_unique<FakeRecording>(60, 10'000, true, std::chrono::milliseconds(25)), config);
  source.open();
  const auto frames = drain(source);
  const FrameSourceStats stats = source.stats();
  ASSERT_GE(frames.size(), 10u);
  EXPECT_EQ(stats.frames_read, frames.size());
  EXPECT_EQ(stats.frames_read + stats.frames_dropped, 60u);
  for (std::size_t i = 1; i < frames.size(); ++i) {
    EXPECT_GT(frames[i].first->sequence, frames[i - 1].first->sequence);
    const auto gap = frames[i].first->sequence - frames[i - 1].first->sequence;
    EXPECT_LE(gap, 20) << "frame " << frames[i].first->sequence << ": fell behind";
  }
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
