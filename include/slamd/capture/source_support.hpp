#pragma once
// Helpers shared by the frame sources: thread-safe statistics and the checks every frame passes
// before a source hands it out.
//
// SourceCounters is written by the thread that owns the source (and, for LCM, its receive
// thread) and read by any thread through snapshot(); a mutex guards it because skips are rare
// and stats() is called about once a second.
//
// FrameGate::check() validates a decoded frame (types and sizes against its intrinsics, see
// RgbdFrame::validationError) and enforces strictly increasing timestamps; a source calls it
// once per frame, on its own thread.

#include <cstdint>
#include <mutex>
#include <string>

#include "slamd/capture/frame_source.hpp"

namespace slamd {

class SourceCounters {
 public:
  void frameRead();
  /// Counts a skipped frame and logs `message` (warn level) under `component`.
  void skipped(const char* component, const std::string& message);
  void dropped(std::uint64_t count = 1);
  /// A frame passed over unread by a player behind its schedule (also counted as dropped).
  void droppedBehindSchedule();
  /// A frame received faster than the camera's rate (also counted as dropped).
  void droppedOverRate();
  void reconnected();
  void reanchored();
  /// Records a failure message (e.g. a disconnect) without counting a frame.
  void failure(const char* component, const std::string& message);
  FrameSourceStats snapshot() const;

 private:
  mutable std::mutex mutex_;
  FrameSourceStats stats_;
};

class FrameGate {
 public:
  /// Empty when the frame may be delivered (and then remembers its timestamp), otherwise a
  /// sentence saying why not, prefixed with `what` (a file or message name).
  std::string check(const RgbdFrame& frame, const std::string& what);
  void reset() { has_last_ = false; }

 private:
  bool has_last_ = false;
  Utime last_utime_ = 0;
};

/// Guards a live stream against timestamps that do not fit its clock. The stream's clock is the
/// offset between frame timestamps and their arrival times (steady clock), taken from the frames
/// accepted so far. A frame whose offset is more than max_jump_s from it (one bit-flipped or
/// far-future stamp) is rejected, so it cannot poison the stream. When `reanchor_frames` rejected
/// frames in a row agree with each other (offsets within max_jump_s), the source's clock really
/// jumped (a restarted camera, a log replayed again): the stream re-anchors to them.
/// A frame that only arrives late (its timestamp still after the last accepted one, but later
/// than the clock expects) is a pause in delivery, not a jump: a camera that stalled, a log
/// recorded while its producer was held up, a slow link. It is accepted and the clock follows it.
/// One owner thread.
class StreamClock {
 public:
  enum class Verdict { kAccept, kReject, kReanchor };

  StreamClock(double max_jump_s, int reanchor_frames)
      : max_jump_us_(static_cast<std::int64_t>(max_jump_s * 1e6)),
        reanchor_frames_(reanchor_frames) {}

  /// kReanchor accepts the frame and tells the caller to forget earlier timestamps.
  Verdict check(Utime utime, std::int64_t arrival_steady_ns);
  /// How far (seconds) the last checked frame was from the stream's clock.
  double lastJumpS() const { return static_cast<double>(last_jump_us_) * 1e-6; }

 private:
  std::int64_t max_jump_us_;
  int reanchor_frames_;
  bool anchored_ = false;
  std::int64_t offset_us_ = 0;  ///< utime - arrival of the last accepted frame
  Utime last_utime_ = 0;        ///< timestamp of the last accepted frame
  std::int64_t last_jump_us_ = 0;
  int run_length_ = 0;  ///< consecutive rejected frames agreeing with each other
  std::int64_t run_offset_us_ = 0;
};

/// Builds a kSkipped read after counting it.
FrameRead skipFrame(SourceCounters& counters, const char* component, const std::string& message);

}  // namespace slamd
