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
  void reconnected();
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

/// Builds a kSkipped read after counting it.
FrameRead skipFrame(SourceCounters& counters, const char* component, const std::string& message);

}  // namespace slamd
