#pragma once
// FrameSource: where RGB-D frames come from (camera, recording, dataset, LCM, synthetic world).
//
// Call sequence, on one thread (the capture thread owns its source):
//   source->open();                                 // throws SourceError with a clear message
//   while (true) {
//     FrameRead read = source->next(std::chrono::milliseconds(100));
//     if (read.status == FrameRead::Status::kFrame) use(read.frame);
//     else if (read.status == FrameRead::Status::kEndOfStream) break;
//     // kTimeout: nothing yet (live source); kSkipped: a bad frame was dropped and counted
//   }
//   source->close();
//
// next() never blocks longer than its timeout (so the capture thread can notice a stop request)
// and never throws for bad data: a corrupt, truncated or inconsistent frame is reported as
// kSkipped with a message naming the file or message, and counted in stats().errors.
// Frames come out with strictly increasing timestamps; a frame whose timestamp does not increase
// is skipped and counted.
//
// Recordings that know their frames' timestamps before reading them (datasets, synthetic worlds)
// also offer upcomingUtime() and dropUpcoming(), so that a real-time player that falls behind
// passes over the frames it is too late for without reading, decoding or rendering them.

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/trajectory.hpp"

namespace slamd {

/// The source cannot be opened or has failed for good (missing folder, no device, ...).
class SourceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FrameRead {
  enum class Status { kFrame, kTimeout, kSkipped, kEndOfStream };
  Status status = Status::kTimeout;
  RgbdFramePtr frame;   ///< set when status == kFrame
  std::string message;  ///< why a frame was skipped (kSkipped)
};

struct FrameSourceStats {
  std::uint64_t frames_read = 0;     ///< frames delivered by next()
  std::uint64_t frames_skipped = 0;  ///< bad frames dropped (each also logged once)
  std::uint64_t frames_dropped = 0;  ///< good frames lost to pacing or overflow (live sources)
  /// Of frames_dropped: frames a real-time player passed over unread because it was behind its
  /// schedule (the capture thread, or what shares its CPU, was too slow).
  std::uint64_t frames_behind_schedule = 0;
  /// Of frames_dropped: frames a live source received faster than a camera sends them
  /// (capture.lcm.max_rate_hz), dropped before decoding.
  std::uint64_t frames_over_rate = 0;
  std::uint64_t reconnects = 0;       ///< device re-opens after a disconnect
  std::uint64_t clock_reanchors = 0;  ///< live stream's clock really jumped and was re-anchored
  std::string last_error;             ///< most recent skip or failure message
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;

  /// Opens the source; throws SourceError with a message saying what is wrong and what to do.
  virtual void open() = 0;
  /// The next frame, waiting at most `timeout`.
  virtual FrameRead next(std::chrono::milliseconds timeout) = 0;
  virtual void close() = 0;

  virtual FrameSourceStats stats() const = 0;
  /// e.g. "tum:/data/rgbd_dataset_freiburg1_xyz (798 frames)".
  virtual std::string description() const = 0;
  /// A live source (camera, LCM) produces frames on its own clock and must never be blocked.
  virtual bool isLive() const = 0;
  /// Intrinsics of the frames, when known before the first frame.
  virtual std::optional<CameraIntrinsics> intrinsics() const { return std::nullopt; }
  /// Ground truth T_world_camera for evaluation (TUM groundtruth.txt, synthetic worlds).
  virtual std::optional<Trajectory> groundTruth() const { return std::nullopt; }

  /// The timestamp of the frame `ahead` frames after the one next() would deliver now (ahead 0:
  /// that frame), known without reading it; nullopt past the end, for a list entry that is
  /// already known to be bad, and for sources that cannot tell (live ones).
  virtual std::optional<Utime> upcomingUtime(std::size_t /*ahead*/) const { return std::nullopt; }
  /// Passes over the frame next() would deliver, without reading it, and counts it in
  /// stats().frames_dropped and frames_behind_schedule. False (and nothing happens) when the
  /// source cannot do that; true only where upcomingUtime(0) has a value.
  virtual bool dropUpcoming() { return false; }
};

}  // namespace slamd
