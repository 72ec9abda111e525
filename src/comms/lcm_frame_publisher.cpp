#include "slamd/comms/lcm_frame_publisher.hpp"

#include <lcm/lcm-cpp.hpp>

#include "slamd/common/log.hpp"
#include "slamd/comms/message_codec.hpp"

namespace slamd {

LcmFramePublisherConfig LcmFramePublisherConfig::load(Config& config) {
  LcmFramePublisherConfig out;
  out.channel = config.getString("capture.publish.channel", out.channel);
  if (out.channel.empty()) throw ConfigError("capture.publish.channel must not be empty");
  out.kinect_format =
      config.getChoice("capture.publish.format", "rgbd", {"rgbd", "kinect"}) == "kinect";
  out.encode.color = parseColorEncoding(
      config.getChoice("capture.publish.color", "jpeg", {"jpeg", "png", "rgb8", "bgr8"}));
  out.encode.jpeg_quality = config.getInt("capture.publish.jpeg_quality", 90, 1, 100);
  out.encode.depth =
      parseDepthEncoding(config.getChoice("capture.publish.depth", "zlib", {"zlib", "png", "raw"}));
  out.encode.depth_scale = config.getDouble("capture.publish.depth_scale", 1000.0, 1.0, 1e5);
  return out;
}

LcmFramePublisher::LcmFramePublisher(lcm::LCM& lcm, LcmFramePublisherConfig config)
    : lcm_(lcm), config_(std::move(config)) {}

bool LcmFramePublisher::publish(const RgbdFrame& frame) {
  std::vector<std::uint8_t> bytes;
  try {
    if (config_.kinect_format) {
      bytes = encodeMessage(encodeKinectFrame(frame, config_.encode.color == ColorEncoding::kJpeg,
                                              config_.encode.depth == DepthEncoding::kZlibU16));
    } else {
      bytes = encodeMessage(encodeRgbdFrame(frame, config_.encode));
    }
  } catch (const std::exception& e) {
    ++failures_;
    SLAMD_LOG_WARN("capture.publish")
        << "cannot encode frame " << frame.sequence << ": " << e.what();
    return false;
  }
  if (bytes.empty() ||
      lcm_.publish(config_.channel, bytes.data(), static_cast<unsigned int>(bytes.size())) != 0) {
    ++failures_;
    SLAMD_LOG_WARN("capture.publish") << "cannot publish frame " << frame.sequence << " on "
                                      << config_.channel << " (" << bytes.size() << " bytes)";
    return false;
  }
  ++published_;
  bytes_ += bytes.size();
  return true;
}

}  // namespace slamd
