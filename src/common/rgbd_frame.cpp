#include "slamd/common/rgbd_frame.hpp"

#include <cmath>
#include <limits>
#include <sstream>

#include <opencv2/imgproc.hpp>

namespace slamd {

std::string RgbdFrame::validationError() const {
  std::ostringstream out;
  const std::string intrinsics_error = intrinsics.validationError();
  if (!intrinsics_error.empty()) {
    out << "intrinsics: " << intrinsics_error;
    return out.str();
  }
  const cv::Size expected(intrinsics.width, intrinsics.height);
  if (depth_m.empty()) {
    out << "depth image is empty";
  } else if (depth_m.type() != CV_32FC1) {
    out << "depth image type " << cv::typeToString(depth_m.type()) << " is not CV_32FC1";
  } else if (depth_m.size() != expected) {
    out << "depth image is " << depth_m.cols << "x" << depth_m.rows << ", intrinsics say "
        << expected.width << "x" << expected.height;
  } else if (!color_bgr.empty() && color_bgr.type() != CV_8UC3) {
    out << "colour image type " << cv::typeToString(color_bgr.type()) << " is not CV_8UC3";
  } else if (!color_bgr.empty() && color_bgr.size() != expected) {
    out << "colour image is " << color_bgr.cols << "x" << color_bgr.rows << ", depth is "
        << depth_m.cols << "x" << depth_m.rows;
  } else if (!gray.empty() && (gray.type() != CV_8UC1 || gray.size() != expected)) {
    out << "grey image must be CV_8UC1 of the depth image's size";
  }
  return out.str();
}

cv::Mat depthRawToMeters(const cv::Mat& depth_raw_u16, double depth_scale) {
  CV_Assert(depth_raw_u16.type() == CV_16UC1 && depth_scale > 0.0);
  cv::Mat depth_m(depth_raw_u16.size(), CV_32FC1);
  const float inv_scale = static_cast<float>(1.0 / depth_scale);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int r = 0; r < depth_raw_u16.rows; ++r) {
    const auto* in = depth_raw_u16.ptr<std::uint16_t>(r);
    auto* out = depth_m.ptr<float>(r);
    for (int c = 0; c < depth_raw_u16.cols; ++c) {
      out[c] = in[c] == 0 ? nan : static_cast<float>(in[c]) * inv_scale;
    }
  }
  return depth_m;
}

cv::Mat depthMetersToRaw(const cv::Mat& depth_m, double depth_scale) {
  CV_Assert(depth_m.type() == CV_32FC1 && depth_scale > 0.0);
  cv::Mat raw(depth_m.size(), CV_16UC1);
  for (int r = 0; r < depth_m.rows; ++r) {
    const auto* in = depth_m.ptr<float>(r);
    auto* out = raw.ptr<std::uint16_t>(r);
    for (int c = 0; c < depth_m.cols; ++c) {
      const double value = std::round(static_cast<double>(in[c]) * depth_scale);
      out[c] = (std::isfinite(value) && value > 0.0 && value <= 65535.0)
                   ? static_cast<std::uint16_t>(value)
                   : std::uint16_t{0};
    }
  }
  return raw;
}

void ensureGray(RgbdFrame& frame) {
  if (frame.gray.empty() && !frame.color_bgr.empty()) {
    cv::cvtColor(frame.color_bgr, frame.gray, cv::COLOR_BGR2GRAY);
  }
}

}  // namespace slamd
