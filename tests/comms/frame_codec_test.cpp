#include "slamd/comms/frame_codec.hpp"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace slamd {
namespace {

RgbdFrame makeFrame(int width = 64, int height = 48) {
  RgbdFrame frame;
  frame.utime = 1'000'000;
  frame.sequence = 5;
  frame.intrinsics.width = width;
  frame.intrinsics.height = height;
  frame.intrinsics.fx = frame.intrinsics.fy = 52.5;
  frame.intrinsics.cx = width / 2.0 - 0.5;
  frame.intrinsics.cy = height / 2.0 - 0.5;
  frame.color_bgr = cv::Mat(height, width, CV_8UC3);
  frame.depth_m = cv::Mat(height, width, CV_32FC1);
  std::mt19937 rng(42);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      frame.color_bgr.at<cv::Vec3b>(r, c) =
          cv::Vec3b(static_cast<uchar>(r * 4), static_cast<uchar>(c * 4), 128);
      // Millimetre-exact depths, with holes.
      frame.depth_m.at<float>(r, c) = (r * c) % 7 == 0
                                          ? std::numeric_limits<float>::quiet_NaN()
                                          : static_cast<float>(500 + (rng() % 4000)) / 1000.0f;
    }
  }
  ensureGray(frame);
  return frame;
}

void expectDepthEqual(const cv::Mat& a, const cv::Mat& b, float tolerance) {
  ASSERT_EQ(a.size(), b.size());
  for (int r = 0; r < a.rows; ++r) {
    for (int c = 0; c < a.cols; ++c) {
      const float x = a.at<float>(r, c);
      const float y = b.at<float>(r, c);
      if (std::isnan(x)) {
        EXPECT_TRUE(std::isnan(y)) << r << "," << c;
      } else {
        EXPECT_NEAR(x, y, tolerance) << r << "," << c;
      }
    }
  }
}

TEST(FrameCodec, LosslessEncodingsRoundTripExactly) {
  const RgbdFrame frame = makeFrame();
  for (ColorEncoding color : {ColorEncoding::kRgb8, ColorEncoding::kBgr8, ColorEncoding::kPng}) {
    for (DepthEncoding depth :
         {DepthEncoding::kRawU16, DepthEncoding::kPngU16, DepthEncoding::kZlibU16}) {
      FrameEncodeOptions options;
      options.color = color;
      options.depth = depth;
      const RgbdFrame back = decodeRgbdFrame(encodeRgbdFrame(frame, options));
      EXPECT_EQ(back.utime, frame.utime);
      EXPECT_EQ(back.sequence, frame.sequence);
      EXPECT_EQ(back.intrinsics, frame.intrinsics);
      EXPECT_EQ(cv::norm(back.color_bgr, frame.color_bgr, cv::NORM_INF), 0.0);
      expectDepthEqual(back.depth_m, frame.depth_m, 1e-6f);
    }
  }
}

TEST(FrameCodec, JpegColourIsCloseAndDepthStillExact) {
  const RgbdFrame frame = makeFrame();
  FrameEncodeOptions options;
  options.color = ColorEncoding::kJpeg;
  options.jpeg_quality = 95;
  const RgbdFrame back = decodeRgbdFrame(encodeRgbdFrame(frame, options));
  EXPECT_LT(cv::norm(back.color_bgr, frame.color_bgr, cv::NORM_L1) / (64 * 48 * 3), 3.0);
  expectDepthEqual(back.depth_m, frame.depth_m, 1e-6f);
}

TEST(FrameCodec, MismatchedByteCountsAreRejectedWithAReason) {
  const RgbdFrame frame = makeFrame();
  FrameEncodeOptions options;
  options.color = ColorEncoding::kBgr8;
  options.depth = DepthEncoding::kRawU16;
  auto msg = encodeRgbdFrame(frame, options);
  msg.color_data.pop_back();
  msg.color_nbytes--;
  EXPECT_THROW(decodeRgbdFrame(msg), FrameDecodeError);
  msg = encodeRgbdFrame(frame, options);
  msg.width = 65;
  EXPECT_THROW(decodeRgbdFrame(msg), FrameDecodeError);
  msg = encodeRgbdFrame(frame, options);
  msg.depth_encoding = 42;
  try {
    decodeRgbdFrame(msg);
    FAIL();
  } catch (const FrameDecodeError& e) {
    EXPECT_NE(std::string(e.what()).find("depth encoding 42"), std::string::npos) << e.what();
  }
}

TEST(FrameCodec, CorruptCompressedDataIsRejected) {
  const RgbdFrame frame = makeFrame();
  FrameEncodeOptions options;
  options.color = ColorEncoding::kJpeg;
  options.depth = DepthEncoding::kZlibU16;
  auto msg = encodeRgbdFrame(frame, options);
  msg.depth_data.resize(msg.depth_data.size() / 2);  // truncated zlib stream
  EXPECT_THROW(decodeRgbdFrame(msg), FrameDecodeError);
  msg = encodeRgbdFrame(frame, options);
  for (std::size_t i = 0; i < msg.color_data.size(); ++i)
    msg.color_data[i] = static_cast<uint8_t>(i * 31);
  EXPECT_THROW(decodeRgbdFrame(msg), FrameDecodeError);  // garbage JPEG
  options.depth = DepthEncoding::kPngU16;
  msg = encodeRgbdFrame(frame, options);
  msg.depth_data.resize(40);  // truncated PNG
  EXPECT_THROW(decodeRgbdFrame(msg), FrameDecodeError);
}

TEST(FrameCodec, KinectFrameRoundTripsInEveryFormat) {
  const RgbdFrame frame = makeFrame();
  for (bool jpeg : {false, true}) {
    for (bool zlib : {false, true}) {
      const RgbdFrame back =
          decodeKinectFrame(encodeKinectFrame(frame, jpeg, zlib), frame.intrinsics);
      EXPECT_EQ(back.utime, frame.utime);
      EXPECT_EQ(back.depth_utime, 0);  // depth taken with colour
      expectDepthEqual(back.depth_m, frame.depth_m, 1e-6f);
      if (!jpeg) {
        EXPECT_EQ(cv::norm(back.color_bgr, frame.color_bgr, cv::NORM_INF), 0.0);
      }
    }
  }
}

TEST(FrameCodec, KinectFrameKeepsTheDepthImagesOwnTime) {
  RgbdFrame frame = makeFrame();
  frame.depth_utime = frame.utime - 12000;  // a Kinect v1's depth, 12 ms before the colour
  const kinect::frame_msg_t msg = encodeKinectFrame(frame, false, false);
  EXPECT_EQ(msg.image.timestamp, frame.utime);
  EXPECT_EQ(msg.depth.timestamp, frame.depth_utime);
  const RgbdFrame back = decodeKinectFrame(msg, frame.intrinsics);
  EXPECT_EQ(back.utime, frame.utime);
  EXPECT_EQ(back.depth_utime, frame.depth_utime);
  EXPECT_EQ(back.depthUtime(), frame.utime - 12000);
}

TEST(FrameCodec, KinectUnsupportedFormatsAreNamedInTheError) {
  const RgbdFrame frame = makeFrame();
  auto msg = encodeKinectFrame(frame, false, false);
  msg.image.image_data_format = kinect::image_msg_t::VIDEO_BAYER;
  try {
    decodeKinectFrame(msg, frame.intrinsics);
    FAIL();
  } catch (const FrameDecodeError& e) {
    EXPECT_NE(std::string(e.what()).find("colour format 1"), std::string::npos) << e.what();
  }
  msg = encodeKinectFrame(frame, false, false);
  msg.depth.depth_data_format = kinect::depth_msg_t::DEPTH_11BIT;
  try {
    decodeKinectFrame(msg, frame.intrinsics);
    FAIL();
  } catch (const FrameDecodeError& e) {
    EXPECT_NE(std::string(e.what()).find("depth format 0"), std::string::npos) << e.what();
  }
}

FrameEncodeOptions withPngDepth(ColorEncoding color) {
  FrameEncodeOptions options;
  options.color = color;
  options.depth = DepthEncoding::kPngU16;
  return options;
}

// Overwrites the image size a PNG (IHDR) or baseline JPEG (SOF0) header declares.
void patchHeaderSize(std::vector<std::uint8_t>& bytes, int width, int height) {
  auto put = [&](std::size_t at, std::uint32_t value, int count) {
    for (int i = 0; i < count; ++i) {
      bytes[at + i] = static_cast<std::uint8_t>(value >> (8 * (count - 1 - i)));
    }
  };
  if (bytes[0] == 0x89) {
    put(16, static_cast<std::uint32_t>(width), 4);
    put(20, static_cast<std::uint32_t>(height), 4);
    return;
  }
  for (std::size_t pos = 2; pos + 9 < bytes.size();
       pos += 2 + (bytes[pos + 2] << 8 | bytes[pos + 3])) {
    if (bytes[pos + 1] == 0xC0) {
      put(pos + 5, static_cast<std::uint32_t>(height), 2);
      put(pos + 7, static_cast<std::uint32_t>(width), 2);
      return;
    }
  }
  FAIL() << "no SOF0 marker";
}

TEST(FrameCodec, HeaderSizesAreReadWithoutDecoding) {
  const RgbdFrame frame = makeFrame(64, 48);
  for (const ColorEncoding color : {ColorEncoding::kPng, ColorEncoding::kJpeg}) {
    const slamd::rgbd_frame_t message = encodeRgbdFrame(frame, withPngDepth(color));
    EXPECT_EQ(encodedImageSize(message.color_data.data(), message.color_data.size()),
              cv::Size(64, 48));
    EXPECT_EQ(encodedImageSize(message.depth_data.data(), message.depth_data.size()),
              cv::Size(64, 48));
  }
  const std::uint8_t garbage[] = {1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12, 13,
                                  14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25};
  EXPECT_FALSE(encodedImageSize(garbage, sizeof garbage).has_value());
}

TEST(FrameCodec, AnImageWhoseHeaderClaimsAnotherSizeIsRejectedBeforeDecoding) {
  // Hostile-input issue, row 5: a 261 kB frame whose PNG depth inflated to 1.38 GB. The header's
  // size must equal the size the message declares; nothing is inflated otherwise.
  const RgbdFrame frame = makeFrame(64, 48);
  for (const ColorEncoding color : {ColorEncoding::kPng, ColorEncoding::kJpeg}) {
    slamd::rgbd_frame_t depth_bomb = encodeRgbdFrame(frame, withPngDepth(color));
    patchHeaderSize(depth_bomb.depth_data, 30000, 30000);
    slamd::rgbd_frame_t color_bomb = encodeRgbdFrame(frame, withPngDepth(color));
    patchHeaderSize(color_bomb.color_data, 30000, 30000);
    for (const auto* message : {&depth_bomb, &color_bomb}) {
      try {
        decodeRgbdFrame(*message);
        ADD_FAILURE() << "decoded";
      } catch (const FrameDecodeError& e) {
        EXPECT_NE(std::string(e.what()).find("header says 30000x30000, message says 64x48"),
                  std::string::npos)
            << e.what();
      }
    }
  }
}

TEST(FrameCodec, AMessageDeclaringMoreThan16MegapixelsIsRejected) {
  slamd::rgbd_frame_t message =
      encodeRgbdFrame(makeFrame(64, 48), withPngDepth(ColorEncoding::kPng));
  message.width = 8192;
  message.height = 8192;
  EXPECT_THROW(decodeRgbdFrame(message), FrameDecodeError);
}

TEST(FrameCodec, EncodingNamesParse) {
  EXPECT_EQ(parseColorEncoding("jpeg"), ColorEncoding::kJpeg);
  EXPECT_EQ(parseDepthEncoding("zlib"), DepthEncoding::kZlibU16);
  EXPECT_THROW(parseColorEncoding("gif"), std::invalid_argument);
}

}  // namespace
}  // namespace slamd
