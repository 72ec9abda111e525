#include "slamd/comms/lcm_frame_publisher.hpp"

#include <lcm/lcm-cpp.hpp>

#include "slamd/common/log.hpp"
#include "slamd/comms/message_codec.hpp"

namespace slamd {

namespace {

const EnumNames<bool> kPublishFormatNames = {
    {false, "rgbd", "slamd.rgbd_frame_t (with intrinsics)"},
    {true, "kinect",
     "kinect.frame_msg_t: JPEG colour when color = jpeg, else raw; zlib depth "
     "when depth = zlib, else raw millimetres"},
};

}  // namespace

const ConfigSchema<LcmFramePublisherConfig>& LcmFramePublisherConfig::schema() {
  using C = LcmFramePublisherConfig;
  static const auto table =
      ConfigSchema<C>("capture.publish")
          .text("channel", &C::channel, "channel of republished frames; not empty")
          .choice("format", &C::kinect_format, kPublishFormatNames, "message type")
          .choice(
              "color", [](auto& c) -> auto& { return c.encode.color; }, colorEncodingNames(),
              "colour encoding")
          .number(
              "jpeg_quality", [](auto& c) -> auto& { return c.encode.jpeg_quality; }, 1, 100, "",
              "JPEG quality")
          .choice(
              "depth", [](auto& c) -> auto& { return c.encode.depth; }, depthEncodingNames(),
              "depth encoding")
          .number(
              "depth_scale", [](auto& c) -> auto& { return c.encode.depth_scale; }, 1.0, 1e5,
              "raw units per metre", "depth units of the encoded image (1000: mm)");
  return table;
}

LcmFramePublisherConfig LcmFramePublisherConfig::load(Config& config) {
  LcmFramePublisherConfig out;
  schema().load(config, out);
  if (out.channel.empty()) throw ConfigError("capture.publish.channel must not be empty");
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
