#include "slamd/capture/paced_source.hpp"

#include <thread>

#include "slamd/common/log.hpp"

namespace slamd {

PacingConfig PacingConfig::load(Config& config) {
  PacingConfig out;
  const std::string mode =
      config.getChoice("capture.pacing.mode", "fastest", {"fastest", "realtime", "fixed"});
  out.mode = mode == "realtime" ? PacingMode::kRealTime
             : mode == "fixed"  ? PacingMode::kFixedRate
                                : PacingMode::kAsFastAsPossible;
  out.speed = config.getDouble("capture.pacing.speed", out.speed, 1e-3, 100.0);
  out.rate_hz = config.getDouble("capture.pacing.rate_hz", out.rate_hz, 1e-3, 1000.0);
  out.max_lag_s = config.getDouble("capture.pacing.max_lag_s", out.max_lag_s, 1e-3, 60.0);
  return out;
}

const char* pacingModeName(PacingMode mode) {
  switch (mode) {
    case PacingMode::kRealTime:
      return "realtime";
    case PacingMode::kFixedRate:
      return "fixed";
    case PacingMode::kAsFastAsPossible:
      break;
  }
  return "fastest";
}

PacedSource::PacedSource(std::unique_ptr<FrameSource> inner, PacingConfig config)
    : inner_(std::move(inner)), config_(config) {}

void PacedSource::open() {
  inner_->open();
  pending_.reset();
  started_ = false;
  index_ = 0;
  if (inner_->isLive() && config_.mode != PacingMode::kAsFastAsPossible) {
    SLAMD_LOG_WARN("capture.pacing")
        << inner_->description() << " is live: frames arrive on the device's clock, pacing "
        << pacingModeName(config_.mode) << " ignored";
  }
}

std::chrono::steady_clock::time_point PacedSource::dueTime(const RgbdFrame& frame) const {
  if (config_.mode == PacingMode::kRealTime) {
    const double elapsed_s = utimeToSeconds(frame.utime - first_utime_) / config_.speed;
    return start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                        std::chrono::duration<double>(elapsed_s));
  }
  const double elapsed_s = static_cast<double>(index_) / config_.rate_hz;
  return start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(elapsed_s));
}

FrameRead PacedSource::next(std::chrono::milliseconds timeout) {
  if (config_.mode == PacingMode::kAsFastAsPossible || inner_->isLive()) {
    return inner_->next(timeout);
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  const auto max_lag = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(config_.max_lag_s));
  while (true) {
    if (!pending_) {
      const auto now = std::chrono::steady_clock::now();
      FrameRead read = inner_->next(std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline > now ? deadline - now : std::chrono::steady_clock::duration::zero()));
      if (read.status != FrameRead::Status::kFrame) return read;
      if (!started_) {
        // The first frame is due now: it anchors the schedule.
        started_ = true;
        start_ = std::chrono::steady_clock::now();
        first_utime_ = read.frame->utime;
        index_ = 0;
        return read;
      }
      ++index_;
      pending_ = std::move(read.frame);
    }
    const auto due = dueTime(*pending_);
    const auto now = std::chrono::steady_clock::now();
    if (now > due + max_lag) {
      // Read too late to be real time (the reader or the decoder fell behind): drop it, as a
      // camera loses the frames nobody read, and try the next one.
      pending_.reset();
      dropped_.fetch_add(1, std::memory_order_relaxed);
      if (now >= deadline) return FrameRead{FrameRead::Status::kTimeout, {}, {}};
      continue;
    }
    if (due > deadline) {
      // Pacing wait, not synchronisation: the frame is not due before the caller's timeout.
      std::this_thread::sleep_until(deadline);
      return FrameRead{FrameRead::Status::kTimeout, {}, {}};
    }
    std::this_thread::sleep_until(due);
    // Released now, as a camera would deliver it: that is its arrival time for latency purposes
    // (the copy is shallow; images are shared).
    auto released = std::make_shared<RgbdFrame>(*pending_);
    released->received_steady_ns = steadyNowNs();
    pending_.reset();
    return FrameRead{FrameRead::Status::kFrame, std::move(released), {}};
  }
}

FrameSourceStats PacedSource::stats() const {
  FrameSourceStats stats = inner_->stats();
  // Frames dropped for lateness were read from the inner source but never delivered.
  const std::uint64_t dropped = dropped_.load(std::memory_order_relaxed);
  stats.frames_dropped += dropped;
  stats.frames_read = stats.frames_read >= dropped ? stats.frames_read - dropped : 0;
  return stats;
}

std::string PacedSource::description() const {
  std::string pacing = pacingModeName(config_.mode);
  if (config_.mode == PacingMode::kRealTime && config_.speed != 1.0) {
    pacing += " x" + std::to_string(config_.speed);
  } else if (config_.mode == PacingMode::kFixedRate) {
    pacing += " " + std::to_string(config_.rate_hz) + " Hz";
  }
  return inner_->description() + ", paced " + pacing;
}

bool PacedSource::isLive() const {
  return inner_->isLive() || config_.mode != PacingMode::kAsFastAsPossible;
}

}  // namespace slamd
