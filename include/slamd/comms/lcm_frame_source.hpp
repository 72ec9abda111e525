#pragma once
// LcmFrameSource: frames received on an LCM channel (`lcm:CHANNEL`), as slamd.rgbd_frame_t or
// kinect.frame_msg_t (the openhumanoids kinect-lcm driver's KINECT_FRAME), live or from
// `lcm-logplayer`.
//
//   LcmFrameSource source("SLAMD_FRAMES", LcmFrameSourceConfig::load(config));
//   source.open();                      // throws SourceError when LCM cannot start (bad URL)
//   FrameRead read = source.next(100ms);
//   source.close();                     // stops and joins the receive thread
//
// Threads: open() starts one receive thread that only copies raw message bytes into a
// DropOldestQueue (capacity capture.lcm.queue_capacity): a slow consumer never blocks LCM, the
// oldest waiting message is evicted and counted in stats().frames_dropped. next() runs on the
// capture thread: it identifies the type by its fingerprint (capture.lcm.format: auto, rgbd or
// kinect), decodes it with decodeMessage<T> (so malformed messages are counted, never thrown),
// then decodes the images (JPEG/PNG/raw colour, PNG/zlib/raw depth). Any failure skips the
// message with a sentence naming the channel, the message number and what is wrong.
// Kinect messages carry no intrinsics: camera.* supplies them (scaled to the message's size).
//
// End of stream: a live channel never ends; with capture.lcm.idle_end_s > 0 the source ends once
// it has received something and then heard nothing for that long (replaying a log to the end).

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "slamd/capture/camera_config.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/capture/source_support.hpp"
#include "slamd/pipeline/drop_oldest_queue.hpp"
#include "slamd/pipeline/wake_signal.hpp"

namespace lcm {
class LCM;
class Subscription;
struct ReceiveBuffer;
}  // namespace lcm

namespace slamd {

enum class LcmFrameFormat { kAuto, kRgbdFrame, kKinectFrame };

/// Keys `capture.lcm.*` (type, default, range, unit and doc of each: its row in
/// lcm_frame_source.cpp, or `slamd --describe-config capture`) and camera.*.
struct LcmFrameSourceConfig {
  std::string url;  ///< capture.lcm.url, else lcm.url, else "" (LCM's default, $LCM_DEFAULT_URL)
  LcmFrameFormat format = LcmFrameFormat::kAuto;
  int queue_capacity = 4;
  double idle_end_s = 0.0;
  double max_time_jump_s = 1.0;  ///< see StreamClock
  int reanchor_frames = 5;
  /// The camera's own frame rate: extra valid frames (a second publisher, a flood) cost no
  /// decode and no tracking step.
  double max_rate_hz = 30.0;
  CameraConfig camera;  ///< for kinect.frame_msg_t

  static const ConfigSchema<LcmFrameSourceConfig>& schema();
  static LcmFrameSourceConfig load(Config& config);
};

class LcmFrameSource : public FrameSource {
 public:
  LcmFrameSource(std::string channel, LcmFrameSourceConfig config);
  /// Receives through an existing LCM instance (e.g. memq:// shared with a publisher in tests);
  /// capture.lcm.url is then ignored. The receive thread calls lcm->handleTimeout(), so nothing
  /// else may handle this instance while the source is open.
  LcmFrameSource(std::shared_ptr<lcm::LCM> lcm, std::string channel, LcmFrameSourceConfig config);
  ~LcmFrameSource() override;
  LcmFrameSource(const LcmFrameSource&) = delete;
  LcmFrameSource& operator=(const LcmFrameSource&) = delete;

  void open() override;
  FrameRead next(std::chrono::milliseconds timeout) override;
  void close() override;
  FrameSourceStats stats() const override;
  std::string description() const override;
  bool isLive() const override { return true; }

  /// Messages the receive thread has taken from LCM and queued (any type, good or bad).
  std::uint64_t messagesReceived() const { return received_.load(std::memory_order_acquire); }

 private:
  struct RawMessage {
    std::vector<std::uint8_t> bytes;
    std::uint64_t number = 0;  ///< 1-based count of messages on this channel
    std::int64_t arrival_steady_ns = 0;
  };

  void onMessage(const lcm::ReceiveBuffer* buffer, const std::string& channel);
  void receiveLoop();
  FrameRead decode(const RawMessage& message);
  /// The stream clock and rate checks, on the message's timestamp before any image is decoded:
  /// a read to return instead of the frame (skipped or dropped), or nullopt to go on.
  std::optional<FrameRead> checkTiming(Utime utime, std::int64_t arrival_steady_ns,
                                       const std::string& what);
  /// Frames closer than this fraction of 1 / max_rate_hz are over the rate (camera jitter
  /// stays well above it).
  static constexpr double kMinIntervalFraction = 0.8;

  std::string channel_;
  LcmFrameSourceConfig config_;
  std::shared_ptr<lcm::LCM> shared_lcm_;  ///< given by the caller, or null
  std::shared_ptr<lcm::LCM> lcm_;         ///< in use while open
  lcm::Subscription* subscription_ = nullptr;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::unique_ptr<DropOldestQueue<RawMessage>> queue_;
  WakeSignal arrived_;
  std::atomic<std::uint64_t> received_{0};
  std::atomic<std::int64_t> last_arrival_ns_{0};
  std::int64_t sequence_ = 0;
  SourceCounters counters_;
  FrameGate gate_;
  std::optional<Utime> last_delivered_utime_;
  StreamClock clock_{1.0, 5};
};

}  // namespace slamd
