// Fuzz target: the frame codec (raw, JPEG and PNG colour; raw, PNG and zlib depth) behind both
// frame messages, slamd.rgbd_frame_t and kinect.frame_msg_t, plus the bare helpers (image header
// sizes, zlib). The input is laid out as frame_codec_layout.hpp says; decoding may only fail
// with FrameDecodeError.

#include <cmath>
#include <limits>

#include "frame_codec_layout.hpp"
#include "fuzz_input.hpp"
#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/comms/frame_codec.hpp"

namespace {

using namespace slamd;
using slamd::fuzz::FrameCodecKind;

constexpr double kDepthScales[] = {
    1000.0, 5000.0, 0.0, -1.0, std::numeric_limits<double>::quiet_NaN(), 1e-300};

void decodeAsRgbdFrame(const fuzz::FrameCodecInput& in) {
  slamd::rgbd_frame_t msg;
  msg.utime = 1;
  msg.sequence = 1;
  msg.width = in.width;
  msg.height = in.height;
  msg.fx = msg.fy = 0.8 * in.width;
  msg.cx = in.width / 2.0;
  msg.cy = in.height / 2.0;
  msg.distortion_model = static_cast<std::int8_t>(in.variant % 3);
  for (double& d : msg.distortion) d = 0.0;
  msg.depth_scale = kDepthScales[(in.variant / 3) % std::size(kDepthScales)];
  msg.color_encoding = static_cast<std::int8_t>(in.color_format);
  msg.color_data = in.color;
  msg.color_nbytes = static_cast<std::int32_t>(msg.color_data.size());
  msg.depth_encoding = static_cast<std::int8_t>(in.depth_format);
  msg.depth_data = in.depth;
  msg.depth_nbytes = static_cast<std::int32_t>(msg.depth_data.size());
  decodeRgbdFrame(msg);
}

void decodeAsKinectFrame(const fuzz::FrameCodecInput& in) {
  kinect::frame_msg_t msg;
  msg.timestamp = 1;
  msg.image.timestamp = 1;
  msg.image.width = static_cast<std::int16_t>(in.width);
  msg.image.height = static_cast<std::int16_t>(in.height);
  msg.image.image_data_format = static_cast<std::int8_t>(in.color_format);
  msg.image.image_data = in.color;
  msg.image.image_data_nbytes = static_cast<std::int32_t>(in.color.size());
  msg.depth.timestamp = 1;
  // Mostly the colour's size; sometimes not, to reach the mismatch check.
  msg.depth.width = static_cast<std::int16_t>(in.variant == 255 ? in.width + 1 : in.width);
  msg.depth.height = static_cast<std::int16_t>(in.height);
  msg.depth.depth_data_format = static_cast<std::int8_t>(in.variant % 11);
  msg.depth.compression = static_cast<std::int8_t>(in.depth_format);
  msg.depth.depth_data = in.depth;
  msg.depth.depth_data_nbytes = static_cast<std::int32_t>(in.depth.size());
  msg.depth.uncompressed_size = in.width * in.height * 2 + (in.variant >= 128 ? 1 : 0);
  decodeKinectFrame(msg, CameraIntrinsics{});
}

void bareCodecs(const fuzz::FrameCodecInput& in) {
  encodedImageSize(in.color.data(), in.color.size());
  checkEncodedImageSize(in.color.data(), in.color.size(), in.width, in.height, "fuzz");
  zlibDecompress(in.depth.data(), in.depth.size(),
                 static_cast<std::size_t>(in.width) * in.height * 2);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz::FuzzInput bytes(data, size);
  fuzz::FrameCodecInput in;
  in.kind = static_cast<FrameCodecKind>(bytes.byte() % 3);
  in.width = bytes.byte() + 1;
  in.height = bytes.byte() + 1;
  in.color_format = bytes.byte();
  in.depth_format = bytes.byte();
  in.variant = bytes.byte();
  in.color = bytes.bytes(bytes.uint16());
  in.depth = bytes.rest();
  try {
    switch (in.kind) {
      case FrameCodecKind::kRgbdFrame:
        decodeAsRgbdFrame(in);
        break;
      case FrameCodecKind::kKinectFrame:
        decodeAsKinectFrame(in);
        break;
      case FrameCodecKind::kBareCodecs:
        bareCodecs(in);
        break;
    }
  } catch (const FrameDecodeError&) {
  }
  return 0;
}
