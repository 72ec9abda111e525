#pragma once
// The input layout of the frame_codec fuzz target, shared with the seed generator so that seeds
// (real encodings of a rendered frame) and the target read the same fields:
//
//   byte     kind            0: slamd.rgbd_frame_t, 1: kinect.frame_msg_t, 2: bare zlib / header
//   byte     width - 1       (1..256)
//   byte     height - 1      (1..256)
//   byte     color format    rgbd_frame_t.color_encoding, or kinect image_data_format
//   byte     depth format    rgbd_frame_t.depth_encoding, or kinect compression
//   byte     variant         rgbd: distortion model and depth scale; kinect: depth format
//   uint16   color_nbytes    (big-endian)
//   ...      color bytes, then the rest: depth bytes
//
// The fields are chosen so that most inputs reach the image decoders (small images, plausible
// intrinsics) instead of stopping at the first size check.

#include <cstdint>
#include <vector>

namespace slamd::fuzz {

enum class FrameCodecKind : std::uint8_t { kRgbdFrame = 0, kKinectFrame = 1, kBareCodecs = 2 };

struct FrameCodecInput {
  FrameCodecKind kind = FrameCodecKind::kRgbdFrame;
  int width = 1;
  int height = 1;
  std::uint8_t color_format = 0;
  std::uint8_t depth_format = 0;
  std::uint8_t variant = 0;
  std::vector<std::uint8_t> color;
  std::vector<std::uint8_t> depth;
};

inline std::vector<std::uint8_t> encodeFrameCodecInput(const FrameCodecInput& input) {
  std::vector<std::uint8_t> out;
  out.push_back(static_cast<std::uint8_t>(input.kind));
  out.push_back(static_cast<std::uint8_t>(input.width - 1));
  out.push_back(static_cast<std::uint8_t>(input.height - 1));
  out.push_back(input.color_format);
  out.push_back(input.depth_format);
  out.push_back(input.variant);
  out.push_back(static_cast<std::uint8_t>(input.color.size() >> 8));
  out.push_back(static_cast<std::uint8_t>(input.color.size() & 0xff));
  out.insert(out.end(), input.color.begin(), input.color.end());
  out.insert(out.end(), input.depth.begin(), input.depth.end());
  return out;
}

}  // namespace slamd::fuzz
