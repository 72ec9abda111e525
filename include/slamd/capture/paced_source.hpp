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
// the frame for the next call).
//
// Falling behind: like a camera, the player hands out the newest frame that is due. Before
// reading, it passes over every frame whose successor is already due, without reading, decoding
// or rendering it (FrameSource::dropUpcoming; counted in stats().frames_dropped and
// frames_behind_schedule), so a slow reader never spends time on frames it would throw away.
// A frame it did read is always delivered, however late. Only a source that cannot pass over
// frames (no upcomingUtime) is read to advance: its frames read more than max_lag_s after they
// were due are dropped and counted the same way.
// A paced source behaves like a live one, and isLive() says so, so the consumer must never
// block it (drop-oldest queue). Live sources pass through unpaced. One owner thread.

#include <atomic>
#include <memory>
#include <string>

#include "slamd/capture/frame_source.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

enum class PacingMode { kAsFastAsPossible, kRealTime, kFixedRate };

/// Keys `capture.pacing.*` (type, default, range, unit and doc of each: its row in
/// paced_source.cpp, or `slamd --describe-config capture`).
struct PacingConfig {
  PacingMode mode = PacingMode::kAsFastAsPossible;
  double speed = 1.0;
  double rate_hz = 30.0;
  double max_lag_s = 0.1;

  static const ConfigSchema<PacingConfig>& schema();
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
  /// Due time of a frame with this timestamp (real time) or index since the first (fixed rate).
  std::chrono::steady_clock::time_point dueTime(Utime utime, std::uint64_t index) const;
  void passOverFramesBehindSchedule();

  std::unique_ptr<FrameSource> inner_;
  PacingConfig config_;
  RgbdFramePtr pending_;
  bool started_ = false;
  std::chrono::steady_clock::time_point start_;
  Utime first_utime_ = 0;
  std::uint64_t index_ = 0;        ///< frames read or passed over since the first
  bool pending_can_skip_ = false;  ///< pending_ came from a source that can pass over frames
  std::atomic<std::uint64_t> dropped_read_late_{0};
};

}  // namespace slamd
