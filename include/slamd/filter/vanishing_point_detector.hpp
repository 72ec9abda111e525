#pragma once
// VanishingPointDetector: the dominant vanishing point of one grey image (paper 002, extended).
//
// Usage (no threads inside, not thread-safe: one instance per thread that detects; it needs no
// EKF, so the daemon can run it on its own thread in parallel with tracking):
//   VanishingPointDetector detector(FilterConfig::load(config), intrinsics);
//   VanishingPoint vp = detector.detect(frame.gray);  // a self-contained value
//   // either hand it to the filter stage (FilterInput::detection, see vanishing_point_filter.hpp)
//   // or, with an EKF at hand:
//   if (vp.status == VanishingPointStatus::kOk) ekf.updateVanishingPoint(vp.pixel,
//                                                                        vp.pixel_covariance);
//
// Steps: resize by image_scale (default 0.5, area averaging), optional Gaussian blur, Canny edges,
// probabilistic Hough segments, each refit by least squares to the edge pixels within one pixel
// of it (or OpenCV's LSD on the resized grey image), segments scaled back to full-resolution
// pixels and (subpixel_lines) refitted to sub-pixel edge positions of the full-resolution image,
// optional removal of segments nearly parallel to the image axes (paper 002), then
// RANSAC over segment pairs: each pair's intersection is scored by the summed length of the
// segments pointing at it (angle between the segment and the ray from its midpoint to the point
// below `inlier_angle_deg`). The best candidate is refined by least squares on its inliers with
// paper 002's normal equations u = (A^T A)^-1 A^T c, each segment a row a_i = unit normal,
// c_i = a_i . p_i (p_i a point of the segment), so a_i . u - c_i is the perpendicular distance in
// pixels from u to the segment's line; inliers are re-chosen around each refined point. The 2x2
// covariance is sigma^2 (A^T A)^-1 with sigma^2 = sum r_i^2 / (n - 2) from the residuals, plus
// min_pixel_sigma_px^2 on the diagonal.
//
// Distortion: when the intrinsics carry plumb-bob coefficients (the image is not undistorted, as
// from the TUM and OpenNI2 sources), every segment's end points are undistorted, so segments,
// the vanishing point and its covariance are in the ideal pinhole image of the same K.
//
// Frames and units: pixels with (0, 0) the centre of the top-left pixel; direction_camera is the
// unit vector K^-1 [u v 1]^T / |.| in the camera optical frame (x right, y down, z forward), so it
// always has z > 0 (a vanishing point fixes a direction only up to sign).
//
// Bad input (empty image, wrong type, size different from the intrinsics) returns a status and is
// counted, never throws.

#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/filter/filter_config.hpp"

namespace slamd {

enum class VanishingPointStatus : std::int8_t {
  kOk = 0,
  kEmptyImage,      ///< no pixels
  kWrongImageType,  ///< not CV_8UC1
  kWrongImageSize,  ///< size differs from the intrinsics
  kTooFewLines,     ///< fewer usable segments than min_supporting_lines
  kNoConsensus,     ///< no candidate with min_supporting_lines inliers
  kDegenerate,      ///< inliers (nearly) parallel: the least-squares system is singular
  kOutsideImage,    ///< point farther outside the image than max_outside_fraction allows
};

const char* vanishingPointStatusName(VanishingPointStatus status);

/// One image line segment, pixels.
struct LineSegment {
  Eigen::Vector2d p1_px;
  Eigen::Vector2d p2_px;
  double length_px() const { return (p2_px - p1_px).norm(); }
};

/// The result of one detect() call: a plain value (no references into the detector), safe to move
/// to another thread.
struct VanishingPoint {
  VanishingPointStatus status = VanishingPointStatus::kEmptyImage;
  /// Vanishing point, pixels (may lie outside the image).
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  /// Covariance of pixel, pixels^2.
  Eigen::Matrix2d pixel_covariance = Eigen::Matrix2d::Identity();
  /// Unit direction of the vanishing lines in the camera optical frame, z > 0.
  Eigen::Vector3d direction_camera = Eigen::Vector3d::UnitZ();
  /// Segments supporting the point (inliers of the final least-squares fit).
  int num_supporting_lines = 0;
  /// Segments left after length and axis-parallel filtering.
  int num_segments = 0;
  /// RMS perpendicular distance of the supporting lines from the point, pixels.
  double rms_residual_px = 0.0;
};

/// Counters since construction (for the status channel).
struct VanishingPointCounters {
  std::int64_t images = 0;
  std::int64_t detected = 0;
  std::int64_t bad_input = 0;     ///< empty, wrong type or wrong size
  std::int64_t not_detected = 0;  ///< too few lines, no consensus, degenerate, outside
};

class VanishingPointDetector {
 public:
  VanishingPointDetector(const CameraIntrinsics& intrinsics, const VanishingPointConfig& config);
  /// The same with the filter's options (uses config.vp only).
  VanishingPointDetector(const FilterConfig& config, const CameraIntrinsics& intrinsics);

  /// Detects the dominant vanishing point of a CV_8UC1 image of the intrinsics' size.
  /// @param gray the frame's grey image (RgbdFrame::gray), not modified, not kept
  /// @return the vanishing point (pixels of this image) or why there is none; never throws
  VanishingPoint detect(const cv::Mat& gray);

  /// The segments of the last detect() call after filtering (for debugging and drawing).
  const std::vector<LineSegment>& segments() const { return segments_; }
  /// Indices into segments() of the last result's supporting lines.
  const std::vector<int>& inliers() const { return inliers_; }
  const VanishingPointCounters& counters() const { return counters_; }
  const VanishingPointConfig& config() const { return config_; }

  /// The vanishing point of given segments (the part of detect() after line extraction); public
  /// so that it can be tested on exact lines.
  VanishingPoint estimateFromSegments(const std::vector<LineSegment>& segments);

 private:
  void extractSegments(const cv::Mat& gray);

  CameraIntrinsics intrinsics_;
  VanishingPointConfig config_;
  std::vector<LineSegment> segments_;
  std::vector<int> inliers_;
  VanishingPointCounters counters_;
  cv::Mat scaled_, blurred_, edges_;      ///< scratch images reused between frames
  cv::Ptr<cv::LineSegmentDetector> lsd_;  ///< only when segment_detector = lsd
};

}  // namespace slamd
