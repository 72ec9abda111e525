#include "slamd/capture/paced_source.hpp"

#include <thread>

#include "slamd/common/log.hpp"

namespace slamd {

namespace {

const EnumNames<PacingMode> kPacingModeNames = {
    {PacingMode::kAsFastAsPossible, "fastest", "as fast as the stages take frames"},
    {PacingMode::kRealTime, "realtime", "on the recorded clock, times speed"},
    {PacingMode::kFixedRate, "fixed", "at rate_hz"},
};

}  // namespace

const ConfigSchema<PacingConfig>& PacingConfig::schema() {
  using C = PacingConfig;
  static const auto table =
      ConfigSchema<C>("capture.pacing")
          .choice("mode", &C::mode, kPacingModeNames, "how recorded frames are paced")
          .number("speed", &C::speed, 1e-3, 100.0, "", "real-time multiplier of realtime")
          .number("rate_hz", &C::rate_hz, 1e-3, 1000.0, "Hz", "frame rate of fixed")
          .number("max_lag_s", &C::max_lag_s, 1e-3, 60.0, "s",
                  "sources that must be read to advance drop frames read later than this");
  return table;
}

PacingConfig PacingConfig::load(Config& config) {
  PacingConfig out;
  schema().load(config, out);
  return out;
}

const char* pacingModeName(PacingMode mode) { return enumText(kPacingModeNames, mode); }

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

std::chrono::steady_clock::time_point PacedSource::dueTime(Utime utime, std::uint64_t index) const {
  const double elapsed_s = config_.mode == PacingMode::kRealTime
                               ? utimeToSeconds(utime - first_utime_) / config_.speed
                               : static_cast<double>(index) / config_.rate_hz;
  return start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(elapsed_s));
}

void PacedSource::passOverFramesBehindSchedule() {
  // The frame next() reads gets index index_ + 1. While the frame after it is already due, a
  // camera would have replaced it: pass over it unread.
  const auto now = std::chrono::steady_clock::now();
  while (true) {
    const std::optional<Utime> after = inner_->upcomingUtime(1);
    if (!after || dueTime(*after, index_ + 2) > now) return;
    if (!inner_->dropUpcoming()) return;
    ++index_;
  }
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
      if (started_) passOverFramesBehindSchedule();
      // A source that could have passed over the frame is not asked to drop it once read: it is
      // the newest frame due (or the next one to come), however long reading it took.
      pending_can_skip_ = inner_->upcomingUtime(0).has_value();
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
    const auto due = dueTime(pending_->utime, index_);  // index_ is the pending frame's
    const auto now = std::chrono::steady_clock::now();
    if (!pending_can_skip_ && now > due + max_lag) {
      // A source that must be read to advance (no upcomingUtime) and was read too late to be
      // real time: drop the frame, as a camera loses the frames nobody read, and read the next.
      pending_.reset();
      dropped_read_late_.fetch_add(1, std::memory_order_relaxed);
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
  // Frames dropped for lateness were read from the inner source but never delivered (frames
  // passed over unread are counted by the inner source).
  const std::uint64_t dropped = dropped_read_late_.load(std::memory_order_relaxed);
  stats.frames_dropped += dropped;
  stats.frames_behind_schedule += dropped;
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
