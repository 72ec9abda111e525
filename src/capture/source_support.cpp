#include "slamd/capture/source_support.hpp"

#include <cstdlib>

#include "slamd/common/log.hpp"

namespace slamd {

void SourceCounters::frameRead() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.frames_read;
}

void SourceCounters::skipped(const char* component, const std::string& message) {
  SLAMD_LOG_WARN(component) << "skipped frame: " << message;
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.frames_skipped;
  stats_.last_error = message;
}

void SourceCounters::dropped(std::uint64_t count) {
  std::lock_guard<std::mutex> lock(mutex_);
  stats_.frames_dropped += count;
}

void SourceCounters::droppedBehindSchedule() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.frames_dropped;
  ++stats_.frames_behind_schedule;
}

void SourceCounters::droppedOverRate() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.frames_dropped;
  ++stats_.frames_over_rate;
}

void SourceCounters::reanchored() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.clock_reanchors;
}

void SourceCounters::reconnected() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.reconnects;
}

void SourceCounters::failure(const char* component, const std::string& message) {
  SLAMD_LOG_WARN(component) << message;
  std::lock_guard<std::mutex> lock(mutex_);
  stats_.last_error = message;
}

FrameSourceStats SourceCounters::snapshot() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

std::string FrameGate::check(const RgbdFrame& frame, const std::string& what) {
  const std::string error = frame.validationError();
  if (!error.empty()) return what + ": " + error;
  if (has_last_ && frame.utime <= last_utime_) {
    return what + ": timestamp " + std::to_string(frame.utime) +
           " us does not increase (previous frame " + std::to_string(last_utime_) + " us)";
  }
  has_last_ = true;
  last_utime_ = frame.utime;
  return {};
}

StreamClock::Verdict StreamClock::check(Utime utime, std::int64_t arrival_steady_ns) {
  const std::int64_t offset_us = utime - arrival_steady_ns / 1000;
  if (!anchored_) {
    anchored_ = true;
    offset_us_ = offset_us;
    last_utime_ = utime;
    last_jump_us_ = 0;
    return Verdict::kAccept;
  }
  last_jump_us_ = offset_us - offset_us_;
  // Within the tolerance, or late but still after the last accepted frame (a pause in delivery).
  const bool arrived_late_in_order = last_jump_us_ < 0 && utime > last_utime_;
  if (std::llabs(last_jump_us_) <= max_jump_us_ || arrived_late_in_order) {
    offset_us_ = offset_us;  // follows slow drift between the two clocks, and pauses
    last_utime_ = utime;
    run_length_ = 0;
    return Verdict::kAccept;
  }
  if (run_length_ > 0 && std::llabs(offset_us - run_offset_us_) <= max_jump_us_) {
    ++run_length_;
  } else {
    run_length_ = 1;
  }
  run_offset_us_ = offset_us;
  if (run_length_ < reanchor_frames_) return Verdict::kReject;
  offset_us_ = offset_us;
  last_utime_ = utime;
  run_length_ = 0;
  return Verdict::kReanchor;
}

FrameRead skipFrame(SourceCounters& counters, const char* component, const std::string& message) {
  counters.skipped(component, message);
  FrameRead read;
  read.status = FrameRead::Status::kSkipped;
  read.message = message;
  return read;
}

}  // namespace slamd
