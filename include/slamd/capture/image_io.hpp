#pragma once
// Strict image decoding for capture: a file or buffer either decodes completely into the expected
// type, or the call fails with a sentence saying what is wrong. Never throws for bad data.
//
// JPEG goes through libjpeg directly because OpenCV's decoder treats corrupt entropy data and
// premature end of file as warnings and returns a half-grey image; here any libjpeg warning is an
// error. PNG and other formats go through cv::imdecode (libpng reports truncation and CRC errors).

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/common/file_io.hpp"  // readFileBytes

namespace slamd {

/// True when the bytes start with the JPEG start-of-image marker.
bool looksLikeJpeg(const std::uint8_t* data, std::size_t size);

/// Decodes a JPEG or PNG colour image into CV_8UC3 BGR. Grey images are expanded to BGR.
/// Returns an empty Mat and sets `error` on failure.
cv::Mat decodeColorImage(const std::uint8_t* data, std::size_t size, std::string& error);

/// Decodes a 16-bit single-channel PNG depth image into CV_16UC1.
cv::Mat decodeDepthImage(const std::uint8_t* data, std::size_t size, std::string& error);

}  // namespace slamd
