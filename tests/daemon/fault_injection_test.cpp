// Fault injection against the whole daemon (in process): a camera that drops out and returns.
//
// DropoutSource wraps the configured source and withholds every frame whose capture time falls
// in given windows, the way a camera that stops delivering (a USB reset, a loose cable) and comes
// back looks to slamd: timeouts, then frames stamped later, taken from a pose the camera moved to
// meanwhile. The daemon must notice each gap and measure poses again soon after frames return;
// the summary reports the gaps and the time to resume.

#include <cstdio>
#include <memory>
#include <utility>
#include <vector>

#include "daemon_fixture.hpp"
#include "slamd/capture/frame_source.hpp"

namespace slamd {
namespace {

class DropoutSource : public FrameSource {
 public:
  /// @param windows_s [start, end) offsets from the first frame's capture time, seconds
  DropoutSource(std::unique_ptr<FrameSource> inner,
                std::vector<std::pair<double, double>> windows_s)
      : inner_(std::move(inner)), windows_s_(std::move(windows_s)) {}

  void open() override { inner_->open(); }
  FrameRead next(std::chrono::milliseconds timeout) override {
    FrameRead read = inner_->next(timeout);
    if (read.status != FrameRead::Status::kFrame) return read;
    if (first_utime_ < 0) first_utime_ = read.frame->utime;
    const double t_s = utimeToSeconds(read.frame->utime - first_utime_);
    for (const auto& [start_s, end_s] : windows_s_) {
      if (t_s >= start_s && t_s < end_s) {
        ++withheld_;
        return FrameRead{};  // a timeout: the camera delivered nothing
      }
    }
    return read;
  }
  void close() override { inner_->close(); }
  FrameSourceStats stats() const override { return inner_->stats(); }
  std::string description() const override { return "dropout(" + inner_->description() + ")"; }
  bool isLive() const override { return inner_->isLive(); }
  std::optional<CameraIntrinsics> intrinsics() const override { return inner_->intrinsics(); }
  std::optional<Trajectory> groundTruth() const override { return inner_->groundTruth(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  std::vector<std::pair<double, double>> windows_s_;
  Utime first_utime_ = -1;
  int withheld_ = 0;
};

using DaemonFaultInjection = DaemonInProcess;

TEST_F(DaemonFaultInjection, ACameraThatDropsOutAndReturnsIsTrackedAgainWithinASecond) {
  // 12 s of the synthetic room at 30 Hz; the camera is gone for 0.6 s, 1.5 s and 3 s.
  Config config = smallSyntheticConfig(360);
  DaemonOverrides overrides;
  const std::vector<std::pair<double, double>> dropouts = {{2.0, 2.6}, {4.0, 5.5}, {7.0, 10.0}};
  overrides.wrap_source = [&](std::unique_ptr<FrameSource> source) -> std::unique_ptr<FrameSource> {
    return std::make_unique<DropoutSource>(std::move(source), dropouts);
  };
  const DaemonSummary summary = runToEnd(config, overrides);
  std::printf(
      "dropouts of 0.6, 1.5 and 3 s: %llu gaps seen (longest %.2f s), tracking measured "
      "again at most %.3f s after the frames returned; %llu of %llu poses measured\n",
      static_cast<unsigned long long>(summary.capture_gaps), summary.longest_capture_gap_s,
      summary.longest_resume_s, static_cast<unsigned long long>(summary.poses_tracked),
      static_cast<unsigned long long>(summary.poses_published));
  EXPECT_EQ(summary.capture_gaps, 3u);
  EXPECT_NEAR(summary.longest_capture_gap_s, 3.0, 0.1);
  EXPECT_TRUE(summary.resumed_after_last_gap);
  EXPECT_LE(summary.longest_resume_s, 1.0);
  EXPECT_FALSE(summary.tracking_lost_at_end);
  // Every frame the camera delivered was tracked and published.
  EXPECT_EQ(summary.frames_captured, summary.poses_published);
}

}  // namespace
}  // namespace slamd
