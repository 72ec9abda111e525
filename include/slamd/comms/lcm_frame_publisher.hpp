#pragma once
// LcmFramePublisher: republishes frames from any source on an LCM channel, as
// slamd.rgbd_frame_t (JPEG colour, PNG or zlib depth by default) or kinect.frame_msg_t, so that a
// capture can be logged with `lcm-logger` and replayed into slamd (`lcm:CHANNEL`).
//
//   lcm::LCM lcm(url);
//   LcmFramePublisher publisher(lcm, LcmFramePublisherConfig::load(config));
//   publisher.publish(*frame);   // false (and counted) when encoding or sending fails
//
// Keys (capture.publish.*): channel (SLAMD_FRAMES), format rgbd|kinect (rgbd), color
// jpeg|png|rgb8|bgr8 (jpeg), jpeg_quality 1..100 (90), depth png|zlib|raw (png),
// depth_scale raw units per metre (1000, millimetres). Kinect messages carry millimetres, JPEG or
// raw RGB colour (colour png/bgr8 become raw RGB) and zlib or raw depth.
// Not thread-safe: one thread publishes (lcm::LCM itself is thread-safe).

#include <cstdint>
#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/comms/frame_codec.hpp"

namespace lcm {
class LCM;
}  // namespace lcm

namespace slamd {

struct LcmFramePublisherConfig {
  std::string channel = "SLAMD_FRAMES";
  bool kinect_format = false;
  FrameEncodeOptions encode;

  /// The `capture.publish.*` keys.
  static const ConfigSchema<LcmFramePublisherConfig>& schema();
  static LcmFramePublisherConfig load(Config& config);
};

class LcmFramePublisher {
 public:
  LcmFramePublisher(lcm::LCM& lcm, LcmFramePublisherConfig config);

  /// Encodes and publishes one frame; returns false (logged once per failure, counted) on error.
  bool publish(const RgbdFrame& frame);

  std::uint64_t published() const { return published_; }
  std::uint64_t failures() const { return failures_; }
  std::uint64_t bytesPublished() const { return bytes_; }
  const LcmFramePublisherConfig& config() const { return config_; }

 private:
  lcm::LCM& lcm_;
  LcmFramePublisherConfig config_;
  std::uint64_t published_ = 0;
  std::uint64_t failures_ = 0;
  std::uint64_t bytes_ = 0;
};

}  // namespace slamd
