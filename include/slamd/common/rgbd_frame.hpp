#pragma once
// RgbdFrame: one registered colour + depth pair in memory, the payload that flows through the
// pipeline (as std::shared_ptr<const RgbdFrame>, immutable once published).
//
// - color_bgr: CV_8UC3 in OpenCV's BGR order (may be empty for depth-only sources).
// - gray: CV_8UC1, derived from colour.
// - depth_m: CV_32FC1 metres along the optical axis (z), NaN where there is no measurement;
//   registered to the colour image (same size and intrinsics).

#include <cstdint>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/time.hpp"

namespace slamd {

struct RgbdFrame {
  Utime utime = 0;  ///< capture time of the colour image
  /// Capture time of the depth image when the camera does not take both at once (a Kinect v1
  /// streams them on separate clocks: TUM fr1 pairs lie up to 17 ms apart); 0 = taken with the
  /// colour image. Tracking moves features' depths to the colour image's time (depthUtime()).
  Utime depth_utime = 0;
  std::int64_t sequence = 0;  ///< source frame counter (+1 per captured frame)
  std::string frame_id = "camera";
  CameraIntrinsics intrinsics;
  cv::Mat color_bgr;  ///< CV_8UC3
  cv::Mat gray;       ///< CV_8UC1
  cv::Mat depth_m;    ///< CV_32FC1 metres, NaN = no data
  /// Monotonic time (steadyNowNs) when the frame entered slamd, for end-to-end latency.
  std::int64_t received_steady_ns = 0;

  /// Empty when the frame is consistent (types, sizes against intrinsics), otherwise a sentence
  /// naming the problem; sources call it before publishing a frame.
  std::string validationError() const;

  /// depth_utime, or utime when the depth was taken with the colour image.
  Utime depthUtime() const { return depth_utime != 0 ? depth_utime : utime; }
};

using RgbdFramePtr = std::shared_ptr<const RgbdFrame>;

/// Converts raw integer depth (CV_16UC1) to metres (CV_32FC1) with NaN for 0:
/// depth_m = raw / depth_scale.
cv::Mat depthRawToMeters(const cv::Mat& depth_raw_u16, double depth_scale);

/// Converts metres (CV_32FC1, NaN/inf/<=0 = no data) to raw CV_16UC1 = round(depth_m *
/// depth_scale), 0 for no data and for values beyond the uint16 range.
cv::Mat depthMetersToRaw(const cv::Mat& depth_m, double depth_scale);

/// Fills gray from color_bgr when gray is empty.
void ensureGray(RgbdFrame& frame);

}  // namespace slamd
