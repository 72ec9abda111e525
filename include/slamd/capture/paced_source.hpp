#pragma once
// PacedSource: a FrameSource decorator that releases recorded frames as fast as possible, in real
// time from their timestamps, or at a fixed rate.
//
//   PacedSource source(std::make_unique<TumSource>(...), PacingConfig::load(config));
//   source.open();
//   FrameRead read = source.next(100ms);   // kTimeout while the next frame is not yet due
//
// Real time: frame i is due at start + (utime_i - utime_0) / speed, where start is the steady
// time the first frame was delivered. Fixed rate: frame i is due at start + i / rate_hz.
// next() waits for the due time but never longer than its timeout (it returns kTimeout and keeps
// the frame for the next call). A frame read more than max_lag_s after it was due is dropped and
// counted in stats().frames_dropped, as a camera loses frames nobody read: a paced source then
// behaves like a live one, and isLive() says so, so the consumer must never block it (drop-oldest
// queue). Live sources pass through unpaced. One owner thread.

#include <atomic>
#include <memory>
#include <string>

#include "slamd/capture/frame_source.hpp"
#include "slamd/common/config.hpp"

namespace slamd {

enum class PacingMode { kAsFastAsPossible, kRealTime, kFixedRate };

struct PacingConfig {
  PacingMode mode = PacingMode::kAsFastAsPossible;  ///< capture.pacing.mode: fastest|realtime|fixed
  double speed = 1.0;      ///< capture.pacing.speed, real-time multiplier, (0, 100]
  double rate_hz = 30.0;   ///< capture.pacing.rate_hz for fixed, (0, 1000]
  double max_lag_s = 0.1;  ///< capture.pacing.max_lag_s, drop frames later than this, (0, 60]

  static PacingConfig load(Config& config);
};

const char* pacingModeName(PacingMode mode);

class PacedSource : public FrameSource {
 public:
  PacedSource(std::unique_ptr<FrameSource> inner, PacingConfig config);

  void open() override;
  FrameRead next(std::chrono::milliseconds timeout) override;
  void close() override { inner_->close(); }
  FrameSourceStats stats() const override;
  std::string description() const override;
  bool isLive() const override;
  std::optional<CameraIntrinsics> intrinsics() const override { return inner_->intrinsics(); }
  std::optional<Trajectory> groundTruth() const override { return inner_->groundTruth(); }

  FrameSource& inner() { return *inner_; }
  const FrameSource& inner() const { return *inner_; }

 private:
  std::chrono::steady_clock::time_point dueTime(const RgbdFrame& frame) const;

  std::unique_ptr<FrameSource> inner_;
  PacingConfig config_;
  RgbdFramePtr pending_;
  bool started_ = false;
  std::chrono::steady_clock::time_point start_;
  Utime first_utime_ = 0;
  std::uint64_t index_ = 0;  ///< frames read from the inner source since the first
  std::atomic<std::uint64_t> dropped_{0};
};

}  // namespace slamd
