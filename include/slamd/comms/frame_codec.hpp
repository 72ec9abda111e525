#pragma once
// Conversions between RgbdFrame and the frame messages slamd reads and writes:
// slamd.rgbd_frame_t (slamd's own) and kinect.frame_msg_t (the openhumanoids kinect-lcm driver).
//
// Decoding checks every field against the others (sizes, byte counts, encodings) and throws
// FrameDecodeError with a sentence naming what is wrong; it never crashes on bad bytes.

#include <optional>
#include <stdexcept>
#include <string>

#include "kinect/frame_msg_t.hpp"
#include "slamd/common/config_schema.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/rgbd_frame_t.hpp"

namespace slamd {

class FrameDecodeError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class ColorEncoding { kRgb8, kBgr8, kJpeg, kPng };
enum class DepthEncoding { kRawU16, kPngU16, kZlibU16 };

/// The configuration texts of the encodings (capture.publish.color, capture.publish.depth).
const EnumNames<ColorEncoding>& colorEncodingNames();
const EnumNames<DepthEncoding>& depthEncodingNames();
/// Parses "rgb8|bgr8|jpeg|png" and "raw|png|zlib"; throws std::invalid_argument otherwise.
ColorEncoding parseColorEncoding(const std::string& text);
DepthEncoding parseDepthEncoding(const std::string& text);

struct FrameEncodeOptions {
  ColorEncoding color = ColorEncoding::kJpeg;
  int jpeg_quality = 90;                          ///< 1..100
  DepthEncoding depth = DepthEncoding::kZlibU16;  ///< zlib: a quarter of PNG's decode time
  double depth_scale = 1000.0;                    ///< raw units per metre (1000: millimetres)
  int png_compression = 1;                        ///< 0..9; 1 is fast and still ~2.5x smaller
};

slamd::rgbd_frame_t encodeRgbdFrame(const RgbdFrame& frame, const FrameEncodeOptions& options);
RgbdFrame decodeRgbdFrame(const slamd::rgbd_frame_t& message);

/// kinect.frame_msg_t with JPEG or raw RGB colour and zlib or raw millimetre depth.
kinect::frame_msg_t encodeKinectFrame(const RgbdFrame& frame, bool jpeg_color, bool zlib_depth);
/// The kinect message carries no intrinsics: they come from configuration. Formats other than
/// VIDEO_RGB / VIDEO_RGB_JPEG colour and DEPTH_MM depth are rejected with an error naming them.
RgbdFrame decodeKinectFrame(const kinect::frame_msg_t& message, const CameraIntrinsics& intrinsics);

/// The width and height a PNG (IHDR) or JPEG (start-of-frame marker) header declares, read
/// without decoding; nullopt when the bytes are neither or the header is cut short. Decoders check
/// it against the size the message declares before inflating anything, so a small message cannot
/// make them allocate for a huge image.
std::optional<cv::Size> encodedImageSize(const std::uint8_t* data, std::size_t size);

/// Throws FrameDecodeError unless the PNG/JPEG header declares exactly width x height.
void checkEncodedImageSize(const std::uint8_t* data, std::size_t size, int width, int height,
                           const std::string& what);

/// zlib helpers (raw deflate stream with zlib header), throwing FrameDecodeError on failure.
std::vector<std::uint8_t> zlibCompress(const std::uint8_t* data, std::size_t size, int level);
std::vector<std::uint8_t> zlibDecompress(const std::uint8_t* data, std::size_t size,
                                         std::size_t expected_size);

}  // namespace slamd
