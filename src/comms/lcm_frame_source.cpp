#include "slamd/comms/lcm_frame_source.hpp"

#include <pthread.h>

#include <cstdio>
#include <sstream>

#include <lcm/lcm-cpp.hpp>
#include <opencv2/imgproc.hpp>

#include "slamd/capture/image_io.hpp"
#include "slamd/common/log.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/frame_codec.hpp"
#include "slamd/comms/message_codec.hpp"

namespace slamd {

namespace {

constexpr const char* kComponent = "capture.lcm";

// LCM encodes a message's type fingerprint as its first 8 bytes, big-endian.
bool hasFingerprint(const std::vector<std::uint8_t>& bytes, std::int64_t hash) {
  if (bytes.size() < 8) return false;
  std::uint64_t value = 0;
  for (int i = 0; i < 8; ++i) value = (value << 8) | bytes[static_cast<std::size_t>(i)];
  return static_cast<std::int64_t>(value) == hash;
}

std::string fingerprintText(const std::vector<std::uint8_t>& bytes) {
  std::string text = "0x";
  char hex[3];
  for (std::size_t i = 0; i < 8 && i < bytes.size(); ++i) {
    std::snprintf(hex, sizeof(hex), "%02x", bytes[i]);
    text += hex;
  }
  return text;
}

// frame_codec decodes JPEG with OpenCV, which turns corrupt or truncated data into a half-grey
// image with only a warning on stderr. Capture decodes JPEG colour strictly first (any libjpeg
// warning is an error) and hands the codec the raw pixels instead.
// Returns an empty string, or why the JPEG is bad.
std::string strictJpegToRaw(std::vector<std::uint8_t>& data, bool rgb_order, int width,
                            int height) {
  try {
    // Before libjpeg allocates for whatever size the header claims.
    checkEncodedImageSize(data.data(), data.size(), width, height, "JPEG colour");
  } catch (const FrameDecodeError& e) {
    return e.what();
  }
  std::string error;
  cv::Mat bgr = decodeColorImage(data.data(), data.size(), error);
  if (bgr.empty()) return "JPEG colour: " + error;
  if (rgb_order) cv::cvtColor(bgr, bgr, cv::COLOR_BGR2RGB);
  data.assign(bgr.datastart, bgr.dataend);
  return {};
}

}  // namespace

namespace {

const EnumNames<LcmFrameFormat> kLcmFrameFormatNames = {
    {LcmFrameFormat::kAuto, "auto", "whichever type the first message has"},
    {LcmFrameFormat::kRgbdFrame, "rgbd", "slamd.rgbd_frame_t"},
    {LcmFrameFormat::kKinectFrame, "kinect", "kinect.frame_msg_t (intrinsics from camera.*)"},
};

}  // namespace

const ConfigSchema<LcmFrameSourceConfig>& LcmFrameSourceConfig::schema() {
  using C = LcmFrameSourceConfig;
  static const auto table =
      ConfigSchema<C>("capture.lcm")
          .text("url", &C::url, "LCM URL of the frame source; empty = lcm.url")
          .describedDefault("lcm.url")
          .choice("format", &C::format, kLcmFrameFormatNames, "message type of the frames")
          .number("queue_capacity", &C::queue_capacity, 1, 1000, "messages",
                  "received frames waiting to be read")
          .number("idle_end_s", &C::idle_end_s, 0.0, 3600.0, "s",
                  "end the stream after this long without a frame; 0 = never")
          .number("max_time_jump_s", &C::max_time_jump_s, 1e-3, 86400.0, "s",
                  "a frame whose timestamp is further than this from the stream's clock is "
                  "rejected")
          .number("reanchor_frames", &C::reanchor_frames, 1, 1000, "frames",
                  "rejected frames in a row, agreeing with each other, after which the stream's "
                  "clock is re-anchored (it jumped for real)")
          .number("max_rate_hz", &C::max_rate_hz, 0.0, 1000.0, "Hz",
                  "the camera's frame rate (60 for a 60 Hz mode); a frame stamped less than "
                  "0.8 / max_rate_hz after the previous one is dropped before decoding, and "
                  "counted; 0 = no limit (logs replayed faster than recorded)");
  return table;
}

LcmFrameSourceConfig LcmFrameSourceConfig::load(Config& config) {
  LcmFrameSourceConfig out;
  // The program's own LCM URL (lcm.url, set by --lcm-url) unless capture has its own.
  out.url = LcmConfig::load(config).url;
  schema().load(config, out);
  out.camera = CameraConfig::load(config, 1000.0);
  return out;
}

LcmFrameSource::LcmFrameSource(std::string channel, LcmFrameSourceConfig config)
    : channel_(std::move(channel)), config_(std::move(config)) {}

LcmFrameSource::LcmFrameSource(std::shared_ptr<lcm::LCM> lcm, std::string channel,
                               LcmFrameSourceConfig config)
    : channel_(std::move(channel)), config_(std::move(config)), shared_lcm_(std::move(lcm)) {}

LcmFrameSource::~LcmFrameSource() { close(); }

void LcmFrameSource::open() {
  close();
  lcm_ = shared_lcm_ ? shared_lcm_ : std::make_shared<lcm::LCM>(config_.url);
  if (!lcm_->good()) {
    lcm_.reset();
    throw SourceError("cannot start LCM with URL '" + config_.url +
                      "' (check capture.lcm.url / --lcm-url and that multicast is routed)");
  }
  queue_ = std::make_unique<DropOldestQueue<RawMessage>>(
      static_cast<std::size_t>(config_.queue_capacity));
  subscription_ = lcm_->subscribe(channel_, &LcmFrameSource::onMessage, this);
  stop_.store(false, std::memory_order_relaxed);
  received_.store(0, std::memory_order_relaxed);
  last_arrival_ns_.store(0, std::memory_order_relaxed);
  gate_.reset();
  clock_ = StreamClock(config_.max_time_jump_s, config_.reanchor_frames);
  thread_ = std::thread([this] { receiveLoop(); });
  SLAMD_LOG_INFO(kComponent) << "listening on " << description();
}

void LcmFrameSource::receiveLoop() {
  pthread_setname_np(pthread_self(), "slamd:lcm-recv");
  // handleTimeout bounds each wait so that close() is noticed within 50 ms.
  while (!stop_.load(std::memory_order_acquire)) {
    if (lcm_->handleTimeout(50) < 0) {
      counters_.failure(kComponent, "LCM receive failed on " + channel_);
      break;
    }
  }
}

void LcmFrameSource::onMessage(const lcm::ReceiveBuffer* buffer, const std::string& /*channel*/) {
  // Receive thread: copy only. Decoding happens on the capture thread, after the drop-oldest
  // queue, so a slow consumer costs nothing here and never delays LCM's socket.
  RawMessage message;
  const auto* data = static_cast<const std::uint8_t*>(buffer->data);
  message.bytes.assign(data, data + buffer->data_size);
  // Only this thread writes received_ while the source is open. It is counted after the push,
  // so a message counted as received is already in the queue.
  const std::uint64_t number = received_.load(std::memory_order_relaxed) + 1;
  message.number = number;
  message.arrival_steady_ns = steadyNowNs();
  last_arrival_ns_.store(message.arrival_steady_ns, std::memory_order_relaxed);
  queue_->push(std::move(message));
  received_.store(number, std::memory_order_release);
  arrived_.notify();
}

FrameRead LcmFrameSource::next(std::chrono::milliseconds timeout) {
  if (!queue_) return FrameRead{FrameRead::Status::kEndOfStream, {}, {}};
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    const auto seen = arrived_.epoch();
    if (std::optional<RawMessage> message = queue_->tryPop()) return decode(*message);
    if (config_.idle_end_s > 0.0) {
      const std::int64_t last = last_arrival_ns_.load(std::memory_order_relaxed);
      if (last != 0 && steadyNowNs() - last > static_cast<std::int64_t>(config_.idle_end_s * 1e9)) {
        return FrameRead{FrameRead::Status::kEndOfStream, {}, {}};
      }
    }
    if (std::chrono::steady_clock::now() >= deadline) {
      return FrameRead{FrameRead::Status::kTimeout, {}, {}};
    }
    auto wake = deadline;
    if (config_.idle_end_s > 0.0) {
      // Wake up in time to notice the idle end.
      wake = std::min(wake, std::chrono::steady_clock::now() + std::chrono::milliseconds(20));
    }
    arrived_.waitFor(seen, wake);
  }
}

std::optional<FrameRead> LcmFrameSource::checkTiming(Utime utime, std::int64_t arrival_steady_ns,
                                                     const std::string& what) {
  switch (clock_.check(utime, arrival_steady_ns)) {
    case StreamClock::Verdict::kAccept:
      break;
    case StreamClock::Verdict::kReject: {
      std::ostringstream text;
      text << what << ": timestamp " << utime << " us is " << clock_.lastJumpS()
           << " s off the stream's clock (rejected; " << config_.reanchor_frames
           << " agreeing frames in a row re-anchor it)";
      return skipFrame(counters_, kComponent, text.str());
    }
    case StreamClock::Verdict::kReanchor:
      SLAMD_LOG_WARN(kComponent) << channel_ << ": the source's clock jumped by "
                                 << clock_.lastJumpS() << " s; re-anchored after "
                                 << config_.reanchor_frames << " agreeing frames";
      counters_.reanchored();
      gate_.reset();
      last_delivered_utime_.reset();
      return std::nullopt;
  }
  // More frames than a camera sends (a flood of valid frames): dropped before their images are
  // decoded, and counted. Older or equal stamps are left to the gate, which names them.
  if (config_.max_rate_hz > 0.0 && last_delivered_utime_ && utime > *last_delivered_utime_ &&
      utimeToSeconds(utime - *last_delivered_utime_) < kMinIntervalFraction / config_.max_rate_hz) {
    counters_.droppedOverRate();
    return FrameRead{FrameRead::Status::kTimeout, {}, {}};
  }
  return std::nullopt;
}

FrameRead LcmFrameSource::decode(const RawMessage& message) {
  const std::string what = "LCM message #" + std::to_string(message.number) + " on " + channel_;
  const bool is_rgbd = hasFingerprint(message.bytes, slamd::rgbd_frame_t::getHash());
  const bool is_kinect = hasFingerprint(message.bytes, kinect::frame_msg_t::getHash());
  const bool want_rgbd = config_.format != LcmFrameFormat::kKinectFrame;
  const bool want_kinect = config_.format != LcmFrameFormat::kRgbdFrame;
  std::shared_ptr<RgbdFrame> frame;
  std::string error;
  try {
    if (is_rgbd && want_rgbd) {
      auto decoded =
          decodeMessage<slamd::rgbd_frame_t>(message.bytes.data(), message.bytes.size(), &error);
      if (!decoded) return skipFrame(counters_, kComponent, what + ": " + error);
      if (auto refused = checkTiming(decoded->utime, message.arrival_steady_ns, what)) {
        return std::move(*refused);
      }
      if (decoded->color_encoding == slamd::rgbd_frame_t::COLOR_JPEG) {
        error = strictJpegToRaw(decoded->color_data, false, decoded->width, decoded->height);
        if (!error.empty()) return skipFrame(counters_, kComponent, what + ": " + error);
        decoded->color_encoding = slamd::rgbd_frame_t::COLOR_BGR8;
        decoded->color_nbytes = static_cast<std::int32_t>(decoded->color_data.size());
      }
      frame = std::make_shared<RgbdFrame>(decodeRgbdFrame(*decoded));
    } else if (is_kinect && want_kinect) {
      auto decoded =
          decodeMessage<kinect::frame_msg_t>(message.bytes.data(), message.bytes.size(), &error);
      if (!decoded) return skipFrame(counters_, kComponent, what + ": " + error);
      const Utime utime =
          decoded->image.timestamp != 0 ? decoded->image.timestamp : decoded->timestamp;
      if (auto refused = checkTiming(utime, message.arrival_steady_ns, what)) {
        return std::move(*refused);
      }
      if (decoded->image.image_data_format == kinect::image_msg_t::VIDEO_RGB_JPEG) {
        error = strictJpegToRaw(decoded->image.image_data, true, decoded->image.width,
                                decoded->image.height);
        if (!error.empty()) return skipFrame(counters_, kComponent, what + ": " + error);
        decoded->image.image_data_format = kinect::image_msg_t::VIDEO_RGB;
        decoded->image.image_data_nbytes =
            static_cast<std::int32_t>(decoded->image.image_data.size());
      }
      frame = std::make_shared<RgbdFrame>(decodeKinectFrame(*decoded, config_.camera.intrinsics));
    } else {
      std::string expected = config_.format == LcmFrameFormat::kRgbdFrame ? "slamd.rgbd_frame_t"
                             : config_.format == LcmFrameFormat::kKinectFrame
                                 ? "kinect.frame_msg_t"
                                 : "slamd.rgbd_frame_t or kinect.frame_msg_t";
      return skipFrame(counters_, kComponent,
                       what + ": " + std::to_string(message.bytes.size()) +
                           " bytes with type fingerprint " + fingerprintText(message.bytes) +
                           " are not " + expected);
    }
  } catch (const std::exception& e) {
    // FrameDecodeError (inconsistent fields, corrupt images) and anything the decoders throw.
    return skipFrame(counters_, kComponent, what + ": " + e.what());
  }
  // The frame entered slamd when LCM delivered it: time spent waiting in the receive queue and
  // decoding counts towards capture-to-pose latency.
  frame->received_steady_ns = message.arrival_steady_ns;
  if (frame->sequence == 0) frame->sequence = sequence_;
  ++sequence_;
  const std::string gate_error = gate_.check(*frame, what);
  if (!gate_error.empty()) return skipFrame(counters_, kComponent, gate_error);
  last_delivered_utime_ = frame->utime;
  counters_.frameRead();
  return FrameRead{FrameRead::Status::kFrame, std::move(frame), {}};
}

void LcmFrameSource::close() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
  if (queue_) queue_->close();
  if (lcm_ && subscription_ != nullptr) lcm_->unsubscribe(subscription_);
  subscription_ = nullptr;
  lcm_.reset();
}

FrameSourceStats LcmFrameSource::stats() const {
  FrameSourceStats stats = counters_.snapshot();
  if (queue_) stats.frames_dropped += queue_->dropped();
  return stats;
}

std::string LcmFrameSource::description() const {
  return "lcm:" + channel_ + (config_.url.empty() ? std::string() : " (" + config_.url + ")");
}

}  // namespace slamd
