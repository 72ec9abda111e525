#include "slamd/comms/frame_codec.hpp"

#include <zlib.h>

#include <cstring>
#include <limits>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace slamd {

namespace {

/// Largest image a message may declare: 16.8 megapixels, eight times a 1920x1080 RGB-D camera
/// (at most about 50 MB of decoded colour and 32 MB of depth per frame).
constexpr std::size_t kMaxPixels = 4096u * 4096u;

const char* colorEncodingName(int encoding) {
  switch (encoding) {
    case slamd::rgbd_frame_t::COLOR_RGB8:
      return "rgb8";
    case slamd::rgbd_frame_t::COLOR_BGR8:
      return "bgr8";
    case slamd::rgbd_frame_t::COLOR_JPEG:
      return "jpeg";
    case slamd::rgbd_frame_t::COLOR_PNG:
      return "png";
    default:
      return nullptr;
  }
}

std::vector<std::uint8_t> encodeImage(const char* extension, const cv::Mat& image,
                                      const std::vector<int>& params) {
  std::vector<std::uint8_t> bytes;
  if (!cv::imencode(extension, image, bytes, params)) {
    throw std::runtime_error(std::string("cannot encode image as ") + extension);
  }
  return bytes;
}

// Decodes a compressed image, checking that it decoded to the expected type and size.
cv::Mat decodeImage(const std::vector<std::uint8_t>& bytes, int flags, int expected_type, int width,
                    int height, const std::string& what) {
  if (bytes.empty()) throw FrameDecodeError(what + ": no bytes");
  checkEncodedImageSize(bytes.data(), bytes.size(), width, height, what);
  cv::Mat image;
  try {
    image = cv::imdecode(cv::Mat(1, static_cast<int>(bytes.size()), CV_8UC1,
                                 const_cast<std::uint8_t*>(bytes.data())),
                         flags);
  } catch (const cv::Exception& e) {
    throw FrameDecodeError(what + ": corrupt image data (" + e.err + ")");
  }
  if (image.empty()) throw FrameDecodeError(what + ": corrupt or truncated image data");
  if (image.type() != expected_type) {
    throw FrameDecodeError(what + ": decoded to " + cv::typeToString(image.type()) + ", expected " +
                           cv::typeToString(expected_type));
  }
  if (image.cols != width || image.rows != height) {
    throw FrameDecodeError(what + ": image is " + std::to_string(image.cols) + "x" +
                           std::to_string(image.rows) + ", message says " + std::to_string(width) +
                           "x" + std::to_string(height));
  }
  return image;
}

std::uint32_t bigEndian(const std::uint8_t* p, int bytes) {
  std::uint32_t value = 0;
  for (int i = 0; i < bytes; ++i) value = (value << 8) | p[i];
  return value;
}

}  // namespace

std::optional<cv::Size> encodedImageSize(const std::uint8_t* data, std::size_t size) {
  static const std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  if (size >= 24 && std::memcmp(data, kPngSignature, 8) == 0 &&
      std::memcmp(data + 12, "IHDR", 4) == 0) {
    const std::uint32_t width = bigEndian(data + 16, 4);
    const std::uint32_t height = bigEndian(data + 20, 4);
    if (width == 0 || height == 0 || width > 1u << 30 || height > 1u << 30) return std::nullopt;
    return cv::Size(static_cast<int>(width), static_cast<int>(height));
  }
  if (size < 4 || data[0] != 0xFF || data[1] != 0xD8) return std::nullopt;
  // JPEG: walk the marker segments to the first start-of-frame (C0-CF except C4 DHT, C8 JPG
  // and CC DAC): precision, height, width.
  std::size_t pos = 2;
  while (pos + 4 <= size) {
    if (data[pos] != 0xFF) return std::nullopt;
    const std::uint8_t marker = data[pos + 1];
    if (marker == 0xFF) {  // fill byte
      ++pos;
      continue;
    }
    if (marker == 0xD9 || marker == 0xDA) return std::nullopt;   // end of image, or scan data
    if ((marker >= 0xD0 && marker <= 0xD7) || marker == 0x01) {  // no length field
      pos += 2;
      continue;
    }
    const std::size_t length = bigEndian(data + pos + 2, 2);
    if (length < 2) return std::nullopt;
    const bool start_of_frame =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (start_of_frame) {
      if (length < 7 || pos + 9 > size) return std::nullopt;
      const auto height = static_cast<int>(bigEndian(data + pos + 5, 2));
      const auto width = static_cast<int>(bigEndian(data + pos + 7, 2));
      if (width == 0 || height == 0) return std::nullopt;
      return cv::Size(width, height);
    }
    pos += 2 + length;
  }
  return std::nullopt;
}

void checkEncodedImageSize(const std::uint8_t* data, std::size_t size, int width, int height,
                           const std::string& what) {
  const std::optional<cv::Size> declared = encodedImageSize(data, size);
  if (!declared) throw FrameDecodeError(what + ": not a PNG or JPEG image, or its header is cut");
  if (declared->width != width || declared->height != height) {
    throw FrameDecodeError(what + ": image header says " + std::to_string(declared->width) + "x" +
                           std::to_string(declared->height) + ", message says " +
                           std::to_string(width) + "x" + std::to_string(height) + " (not decoded)");
  }
}

namespace {

void checkSize(int width, int height, const std::string& what) {
  if (width <= 0 || height <= 0 ||
      static_cast<std::size_t>(width) * static_cast<std::size_t>(height) > kMaxPixels) {
    throw FrameDecodeError(what + ": invalid image size " + std::to_string(width) + "x" +
                           std::to_string(height));
  }
}

// Little-endian uint16 bytes -> CV_16UC1 (slamd only runs on little-endian hosts; checked here).
cv::Mat rawU16FromBytes(const std::uint8_t* data, std::size_t size, int width, int height,
                        const std::string& what) {
  const std::size_t expected = static_cast<std::size_t>(width) * height * 2;
  if (size != expected) {
    throw FrameDecodeError(what + ": " + std::to_string(size) + " bytes of raw depth, expected " +
                           std::to_string(expected) + " for " + std::to_string(width) + "x" +
                           std::to_string(height));
  }
  cv::Mat raw(height, width, CV_16UC1);
  std::memcpy(raw.data, data, size);
  return raw;
}

}  // namespace

const EnumNames<ColorEncoding>& colorEncodingNames() {
  static const EnumNames<ColorEncoding> names = {
      {ColorEncoding::kJpeg, "jpeg", "JPEG"},
      {ColorEncoding::kPng, "png", "lossless PNG"},
      {ColorEncoding::kRgb8, "rgb8", "raw RGB bytes"},
      {ColorEncoding::kBgr8, "bgr8", "raw BGR bytes"},
  };
  return names;
}

const EnumNames<DepthEncoding>& depthEncodingNames() {
  static const EnumNames<DepthEncoding> names = {
      {DepthEncoding::kZlibU16, "zlib", "zlib-compressed 16-bit (a quarter of PNG's decode time)"},
      {DepthEncoding::kPngU16, "png", "16-bit PNG"},
      {DepthEncoding::kRawU16, "raw", "raw 16-bit little-endian"},
  };
  return names;
}

namespace {

template <typename Enum>
Enum parseEncoding(const EnumNames<Enum>& names, const std::string& text, const char* what) {
  std::string allowed;
  for (const auto& name : names) {
    if (text == name.text) return name.value;
    allowed += (allowed.empty() ? "" : ", ") + std::string(name.text);
  }
  throw std::invalid_argument(std::string(what) + " encoding '" + text + "': allowed values are " +
                              allowed);
}

}  // namespace

ColorEncoding parseColorEncoding(const std::string& text) {
  return parseEncoding(colorEncodingNames(), text, "colour");
}

DepthEncoding parseDepthEncoding(const std::string& text) {
  return parseEncoding(depthEncodingNames(), text, "depth");
}

std::vector<std::uint8_t> zlibCompress(const std::uint8_t* data, std::size_t size, int level) {
  uLongf bound = compressBound(static_cast<uLong>(size));
  std::vector<std::uint8_t> out(bound);
  if (compress2(out.data(), &bound, data, static_cast<uLong>(size), level) != Z_OK) {
    throw std::runtime_error("zlib compression failed");
  }
  out.resize(bound);
  return out;
}

std::vector<std::uint8_t> zlibDecompress(const std::uint8_t* data, std::size_t size,
                                         std::size_t expected_size) {
  std::vector<std::uint8_t> out(expected_size);
  uLongf out_size = static_cast<uLongf>(expected_size);
  const int status = uncompress(out.data(), &out_size, data, static_cast<uLong>(size));
  if (status != Z_OK) {
    throw FrameDecodeError(std::string("zlib depth: ") + (status == Z_BUF_ERROR
                                                              ? "more data than the image size"
                                                              : "corrupt or truncated stream"));
  }
  if (out_size != expected_size) {
    throw FrameDecodeError("zlib depth: " + std::to_string(out_size) + " bytes, expected " +
                           std::to_string(expected_size));
  }
  return out;
}

slamd::rgbd_frame_t encodeRgbdFrame(const RgbdFrame& frame, const FrameEncodeOptions& options) {
  slamd::rgbd_frame_t msg;
  msg.utime = frame.utime;
  msg.sequence = frame.sequence;
  msg.frame_id = frame.frame_id;
  const CameraIntrinsics& k = frame.intrinsics;
  msg.fx = k.fx;
  msg.fy = k.fy;
  msg.cx = k.cx;
  msg.cy = k.cy;
  msg.width = k.width;
  msg.height = k.height;
  msg.distortion_model = k.distortion_model == DistortionModel::kPlumbBob
                             ? slamd::rgbd_frame_t::DISTORTION_PLUMB_BOB
                             : slamd::rgbd_frame_t::DISTORTION_NONE;
  for (std::size_t i = 0; i < k.distortion.size(); ++i) msg.distortion[i] = k.distortion[i];
  msg.depth_scale = options.depth_scale;

  cv::Mat color = frame.color_bgr;
  if (color.empty() && !frame.gray.empty()) cv::cvtColor(frame.gray, color, cv::COLOR_GRAY2BGR);
  if (color.empty()) color = cv::Mat::zeros(k.height, k.width, CV_8UC3);
  switch (options.color) {
    case ColorEncoding::kRgb8: {
      cv::Mat rgb;
      cv::cvtColor(color, rgb, cv::COLOR_BGR2RGB);
      msg.color_encoding = slamd::rgbd_frame_t::COLOR_RGB8;
      msg.color_data.assign(rgb.datastart, rgb.dataend);
      break;
    }
    case ColorEncoding::kBgr8: {
      const cv::Mat bgr = color.isContinuous() ? color : color.clone();
      msg.color_encoding = slamd::rgbd_frame_t::COLOR_BGR8;
      msg.color_data.assign(bgr.datastart, bgr.dataend);
      break;
    }
    case ColorEncoding::kJpeg:
      msg.color_encoding = slamd::rgbd_frame_t::COLOR_JPEG;
      msg.color_data = encodeImage(".jpg", color, {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality});
      break;
    case ColorEncoding::kPng:
      msg.color_encoding = slamd::rgbd_frame_t::COLOR_PNG;
      msg.color_data =
          encodeImage(".png", color, {cv::IMWRITE_PNG_COMPRESSION, options.png_compression});
      break;
  }
  msg.color_nbytes = static_cast<int32_t>(msg.color_data.size());

  const cv::Mat raw = depthMetersToRaw(frame.depth_m, options.depth_scale);
  switch (options.depth) {
    case DepthEncoding::kRawU16:
      msg.depth_encoding = slamd::rgbd_frame_t::DEPTH_RAW_U16;
      msg.depth_data.assign(raw.datastart, raw.dataend);
      break;
    case DepthEncoding::kPngU16:
      msg.depth_encoding = slamd::rgbd_frame_t::DEPTH_PNG_U16;
      msg.depth_data =
          encodeImage(".png", raw, {cv::IMWRITE_PNG_COMPRESSION, options.png_compression});
      break;
    case DepthEncoding::kZlibU16:
      msg.depth_encoding = slamd::rgbd_frame_t::DEPTH_ZLIB_U16;
      msg.depth_data = zlibCompress(
          raw.datastart, static_cast<std::size_t>(raw.dataend - raw.datastart), Z_BEST_SPEED);
      break;
  }
  msg.depth_nbytes = static_cast<int32_t>(msg.depth_data.size());
  return msg;
}

RgbdFrame decodeRgbdFrame(const slamd::rgbd_frame_t& msg) {
  const std::string what = "rgbd_frame_t #" + std::to_string(msg.sequence);
  checkSize(msg.width, msg.height, what);
  RgbdFrame frame;
  frame.utime = msg.utime;
  frame.sequence = msg.sequence;
  frame.frame_id = msg.frame_id;
  CameraIntrinsics& k = frame.intrinsics;
  k.fx = msg.fx;
  k.fy = msg.fy;
  k.cx = msg.cx;
  k.cy = msg.cy;
  k.width = msg.width;
  k.height = msg.height;
  if (msg.distortion_model == slamd::rgbd_frame_t::DISTORTION_PLUMB_BOB) {
    k.distortion_model = DistortionModel::kPlumbBob;
  } else if (msg.distortion_model != slamd::rgbd_frame_t::DISTORTION_NONE) {
    throw FrameDecodeError(what + ": unknown distortion model " +
                           std::to_string(msg.distortion_model));
  }
  for (std::size_t i = 0; i < k.distortion.size(); ++i) k.distortion[i] = msg.distortion[i];
  const std::string intrinsics_error = k.validationError();
  if (!intrinsics_error.empty()) throw FrameDecodeError(what + ": " + intrinsics_error);
  if (!(msg.depth_scale > 0.0) || !std::isfinite(msg.depth_scale)) {
    throw FrameDecodeError(what + ": depth_scale " + std::to_string(msg.depth_scale) +
                           " must be positive");
  }

  const std::size_t pixels = static_cast<std::size_t>(msg.width) * msg.height;
  switch (msg.color_encoding) {
    case slamd::rgbd_frame_t::COLOR_RGB8:
    case slamd::rgbd_frame_t::COLOR_BGR8: {
      if (msg.color_data.size() != pixels * 3) {
        throw FrameDecodeError(what + ": " + std::to_string(msg.color_data.size()) + " bytes of " +
                               colorEncodingName(msg.color_encoding) + " colour, expected " +
                               std::to_string(pixels * 3));
      }
      cv::Mat color(msg.height, msg.width, CV_8UC3,
                    const_cast<std::uint8_t*>(msg.color_data.data()));
      if (msg.color_encoding == slamd::rgbd_frame_t::COLOR_RGB8) {
        cv::cvtColor(color, frame.color_bgr, cv::COLOR_RGB2BGR);
      } else {
        frame.color_bgr = color.clone();
      }
      break;
    }
    case slamd::rgbd_frame_t::COLOR_JPEG:
    case slamd::rgbd_frame_t::COLOR_PNG:
      frame.color_bgr =
          decodeImage(msg.color_data, cv::IMREAD_COLOR, CV_8UC3, msg.width, msg.height,
                      what + " " + colorEncodingName(msg.color_encoding) + " colour");
      break;
    default:
      throw FrameDecodeError(what + ": unknown colour encoding " +
                             std::to_string(msg.color_encoding));
  }

  cv::Mat raw;
  switch (msg.depth_encoding) {
    case slamd::rgbd_frame_t::DEPTH_RAW_U16:
      raw = rawU16FromBytes(msg.depth_data.data(), msg.depth_data.size(), msg.width, msg.height,
                            what + " raw depth");
      break;
    case slamd::rgbd_frame_t::DEPTH_PNG_U16:
      raw = decodeImage(msg.depth_data, cv::IMREAD_ANYDEPTH, CV_16UC1, msg.width, msg.height,
                        what + " png depth");
      break;
    case slamd::rgbd_frame_t::DEPTH_ZLIB_U16: {
      const auto bytes = zlibDecompress(msg.depth_data.data(), msg.depth_data.size(), pixels * 2);
      raw =
          rawU16FromBytes(bytes.data(), bytes.size(), msg.width, msg.height, what + " zlib depth");
      break;
    }
    default:
      throw FrameDecodeError(what + ": unknown depth encoding " +
                             std::to_string(msg.depth_encoding));
  }
  frame.depth_m = depthRawToMeters(raw, msg.depth_scale);
  ensureGray(frame);
  return frame;
}

kinect::frame_msg_t encodeKinectFrame(const RgbdFrame& frame, bool jpeg_color, bool zlib_depth) {
  kinect::frame_msg_t msg;
  msg.timestamp = frame.utime;
  const int width = frame.intrinsics.width;
  const int height = frame.intrinsics.height;
  msg.image.timestamp = frame.utime;
  msg.image.width = static_cast<int16_t>(width);
  msg.image.height = static_cast<int16_t>(height);
  if (jpeg_color) {
    msg.image.image_data_format = kinect::image_msg_t::VIDEO_RGB_JPEG;
    msg.image.image_data = encodeImage(".jpg", frame.color_bgr, {cv::IMWRITE_JPEG_QUALITY, 90});
  } else {
    cv::Mat rgb;
    cv::cvtColor(frame.color_bgr, rgb, cv::COLOR_BGR2RGB);
    msg.image.image_data_format = kinect::image_msg_t::VIDEO_RGB;
    msg.image.image_data.assign(rgb.datastart, rgb.dataend);
  }
  msg.image.image_data_nbytes = static_cast<int32_t>(msg.image.image_data.size());

  msg.depth.timestamp = frame.depthUtime();
  msg.depth.width = static_cast<int16_t>(width);
  msg.depth.height = static_cast<int16_t>(height);
  msg.depth.depth_data_format = kinect::depth_msg_t::DEPTH_MM;
  const cv::Mat raw = depthMetersToRaw(frame.depth_m, 1000.0);
  const std::size_t raw_size = static_cast<std::size_t>(raw.dataend - raw.datastart);
  msg.depth.uncompressed_size = static_cast<int32_t>(raw_size);
  if (zlib_depth) {
    msg.depth.compression = kinect::depth_msg_t::COMPRESSION_ZLIB;
    msg.depth.depth_data = zlibCompress(raw.datastart, raw_size, Z_BEST_SPEED);
  } else {
    msg.depth.compression = kinect::depth_msg_t::COMPRESSION_NONE;
    msg.depth.depth_data.assign(raw.datastart, raw.dataend);
  }
  msg.depth.depth_data_nbytes = static_cast<int32_t>(msg.depth.depth_data.size());
  return msg;
}

RgbdFrame decodeKinectFrame(const kinect::frame_msg_t& msg, const CameraIntrinsics& intrinsics) {
  const std::string what = "kinect frame_msg_t at " + std::to_string(msg.timestamp);
  const int width = msg.image.width;
  const int height = msg.image.height;
  checkSize(width, height, what + " image");
  if (msg.depth.width != width || msg.depth.height != height) {
    throw FrameDecodeError(what + ": depth is " + std::to_string(msg.depth.width) + "x" +
                           std::to_string(msg.depth.height) + ", colour is " +
                           std::to_string(width) + "x" + std::to_string(height));
  }
  RgbdFrame frame;
  frame.utime = msg.image.timestamp != 0 ? msg.image.timestamp : msg.timestamp;
  // The driver stamps each stream on arrival: a Kinect v1's two streams are not synchronised.
  if (msg.depth.timestamp != 0 && msg.depth.timestamp != frame.utime) {
    frame.depth_utime = msg.depth.timestamp;
  }
  frame.intrinsics = (intrinsics.width == width && intrinsics.height == height)
                         ? intrinsics
                         : intrinsics.scaled(width, height);
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  switch (msg.image.image_data_format) {
    case kinect::image_msg_t::VIDEO_RGB: {
      if (msg.image.image_data.size() != pixels * 3) {
        throw FrameDecodeError(what + ": " + std::to_string(msg.image.image_data.size()) +
                               " bytes of VIDEO_RGB colour, expected " +
                               std::to_string(pixels * 3));
      }
      cv::Mat rgb(height, width, CV_8UC3, const_cast<std::uint8_t*>(msg.image.image_data.data()));
      cv::cvtColor(rgb, frame.color_bgr, cv::COLOR_RGB2BGR);
      break;
    }
    case kinect::image_msg_t::VIDEO_RGB_JPEG:
      frame.color_bgr = decodeImage(msg.image.image_data, cv::IMREAD_COLOR, CV_8UC3, width, height,
                                    what + " VIDEO_RGB_JPEG colour");
      break;
    default:
      throw FrameDecodeError(what + ": colour format " +
                             std::to_string(msg.image.image_data_format) +
                             " is not supported (slamd reads VIDEO_RGB=0 and VIDEO_RGB_JPEG=100)");
  }
  if (msg.depth.depth_data_format != kinect::depth_msg_t::DEPTH_MM) {
    throw FrameDecodeError(what + ": depth format " + std::to_string(msg.depth.depth_data_format) +
                           " is not supported (slamd reads DEPTH_MM=5, registered millimetres)");
  }
  cv::Mat raw;
  if (msg.depth.compression == kinect::depth_msg_t::COMPRESSION_ZLIB) {
    if (static_cast<std::size_t>(msg.depth.uncompressed_size) != pixels * 2) {
      throw FrameDecodeError(what + ": uncompressed_size " +
                             std::to_string(msg.depth.uncompressed_size) + ", expected " +
                             std::to_string(pixels * 2));
    }
    const auto bytes =
        zlibDecompress(msg.depth.depth_data.data(), msg.depth.depth_data.size(), pixels * 2);
    raw = rawU16FromBytes(bytes.data(), bytes.size(), width, height, what + " zlib depth");
  } else if (msg.depth.compression == kinect::depth_msg_t::COMPRESSION_NONE) {
    raw = rawU16FromBytes(msg.depth.depth_data.data(), msg.depth.depth_data.size(), width, height,
                          what + " raw depth");
  } else {
    throw FrameDecodeError(what + ": depth compression " + std::to_string(msg.depth.compression) +
                           " is not supported (none=0, zlib=1)");
  }
  frame.depth_m = depthRawToMeters(raw, 1000.0);
  ensureGray(frame);
  return frame;
}

}  // namespace slamd
