#include "slamd/capture/image_io.hpp"

#include <jpeglib.h>

#include <csetjmp>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace slamd {

namespace {

// libjpeg reports fatal errors through error_exit (which must not return: we longjmp back to
// decodeJpeg) and warnings (corrupt data, premature end of file) through emit_message(-1); both
// make the image invalid for slamd.
struct StrictJpegError {
  jpeg_error_mgr manager;
  std::jmp_buf jump;
  std::string message;
};

void strictErrorExit(j_common_ptr info) {
  auto* error = reinterpret_cast<StrictJpegError*>(info->err);
  char text[JMSG_LENGTH_MAX];
  (*info->err->format_message)(info, text);
  error->message = text;
  std::longjmp(error->jump, 1);
}

void strictEmitMessage(j_common_ptr info, int level) {
  if (level >= 0) return;  // trace messages
  auto* error = reinterpret_cast<StrictJpegError*>(info->err);
  if (error->message.empty()) {
    char text[JMSG_LENGTH_MAX];
    (*info->err->format_message)(info, text);
    error->message = text;
  }
}

// Kept free of C++ objects with destructors between setjmp and longjmp (the output Mat is
// allocated by the caller after the header is read, and longjmp only skips trivially
// destructible state).
bool decodeJpegInto(const std::uint8_t* data, std::size_t size, cv::Mat& out,
                    StrictJpegError& error) {
  jpeg_decompress_struct info;
  info.err = jpeg_std_error(&error.manager);
  error.manager.error_exit = strictErrorExit;
  error.manager.emit_message = strictEmitMessage;
  if (setjmp(error.jump)) {
    jpeg_destroy_decompress(&info);
    return false;
  }
  jpeg_create_decompress(&info);
  jpeg_mem_src(&info, data, static_cast<unsigned long>(size));
  jpeg_read_header(&info, TRUE);
  if (info.image_width == 0 || info.image_height == 0 || info.image_width > 16384 ||
      info.image_height > 16384) {
    error.message = "image size out of range";
    jpeg_destroy_decompress(&info);
    return false;
  }
  info.out_color_space = JCS_EXT_BGR;
  // The fast integer DCT: within about a grey level of the exact one, and faster.
  info.dct_method = JDCT_IFAST;
  jpeg_start_decompress(&info);
  out.create(static_cast<int>(info.output_height), static_cast<int>(info.output_width), CV_8UC3);
  while (info.output_scanline < info.output_height) {
    JSAMPROW row = out.ptr<std::uint8_t>(static_cast<int>(info.output_scanline));
    jpeg_read_scanlines(&info, &row, 1);
  }
  jpeg_finish_decompress(&info);
  jpeg_destroy_decompress(&info);
  return error.message.empty();
}

// cv::imdecode keeping depth and channels; empty with `error` set when it fails.
cv::Mat decodeUnchanged(const std::uint8_t* data, std::size_t size, std::string& error) {
  if (size == 0) {
    error = "no image data";
    return {};
  }
  cv::Mat image;
  try {
    image =
        cv::imdecode(cv::Mat(1, static_cast<int>(size), CV_8UC1, const_cast<std::uint8_t*>(data)),
                     cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    error = std::string("corrupt image (") + e.err + ")";
    return {};
  }
  if (image.empty()) error = "not a decodable image, or truncated";
  return image;
}

}  // namespace

bool looksLikeJpeg(const std::uint8_t* data, std::size_t size) {
  return size >= 3 && data[0] == 0xFF && data[1] == 0xD8 && data[2] == 0xFF;
}

cv::Mat decodeColorImage(const std::uint8_t* data, std::size_t size, std::string& error) {
  if (size == 0) {
    error = "no image data";
    return {};
  }
  if (looksLikeJpeg(data, size)) {
    cv::Mat image;
    StrictJpegError jpeg_error;
    if (!decodeJpegInto(data, size, image, jpeg_error)) {
      error = "corrupt JPEG (" + jpeg_error.message + ")";
      return {};
    }
    return image;
  }
  cv::Mat image = decodeUnchanged(data, size, error);
  if (image.empty()) return {};
  if (image.depth() != CV_8U) {
    error = "colour image has " + cv::typeToString(image.type()) + " pixels, expected 8-bit";
    return {};
  }
  if (image.channels() == 1) {
    cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
  } else if (image.channels() == 4) {
    cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
  } else if (image.channels() != 3) {
    error = "colour image has " + std::to_string(image.channels()) + " channels";
    return {};
  }
  return image;
}

cv::Mat decodeDepthImage(const std::uint8_t* data, std::size_t size, std::string& error) {
  cv::Mat image = decodeUnchanged(data, size, error);
  if (image.empty()) return {};
  if (image.type() != CV_16UC1) {
    error = "depth image is " + cv::typeToString(image.type()) +
            ", expected a single-channel 16-bit PNG (CV_16UC1)";
    return {};
  }
  return image;
}

}  // namespace slamd
