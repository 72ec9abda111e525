#pragma once
// VanishingPointFilter: the filter stage's algorithm, one call per odometry increment plus an
// optional grey image; wraps a VanishingPointDetector and a PoseEkf (paper 002's loop).
//
// Usage (owned by the filter thread, or called in a loop over a recorded sequence; no threads
// inside, not thread-safe):
//   VanishingPointFilter filter(FilterConfig::load(config), intrinsics);
//   for each odometry increment:
//     FilterInput in{utime, T_prev_curr, covariance, dt_s, frame.gray, frame.depth_m};
//     FilterOutput out = filter.process(in);  // gray and depth_m may be empty
// or, with the detection done elsewhere (e.g. on a thread running in parallel with tracking, with
// its own VanishingPointDetector built from the same FilterConfig and intrinsics):
//     in.detection = detector.detect(frame.gray);  // then in.gray is not needed and not used
//     FilterOutput out = filter.process(in);
//     publish(out.pose);                              // T_world_camera + 6x6, source kFilter
//     if (out.vanishing_point) publish(out.vanishing_point, out.update);  // vanishing_point_t
//
// With filter.enabled = false the increments are only chained (the pose covariance still grows
// with each odometry covariance), so the output stays comparable; with filter.vanishing_points =
// false images are ignored, with filter.surface_axes = false depth images. Each frame's vanishing
// point updates the EKF first, then its plane axes (strongest first). Conventions: see PoseEkf
// (world = first camera frame, covariances in slamd's x y z rx ry rz order, rotation a right
// perturbation in the camera frame).

#include <cstdint>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/pose_estimate.hpp"
#include "slamd/filter/filter_config.hpp"
#include "slamd/filter/pose_ekf.hpp"
#include "slamd/filter/surface_axes.hpp"
#include "slamd/filter/vanishing_point_detector.hpp"

namespace slamd {

struct FilterInput {
  Utime utime = 0;  ///< capture time of the current frame
  /// Current camera frame -> previous camera frame, metres (odometry_t's T_prev_curr).
  SE3 T_prev_curr = SE3::Identity();
  /// Covariance of T_prev_curr in odometry_t's convention.
  Matrix6d covariance = Matrix6d::Identity() * 1e-6;
  double dt_s = 0.0;  ///< seconds since the previous frame
  cv::Mat gray;       ///< CV_8UC1 image of the current frame, or empty
  cv::Mat depth_m;    ///< CV_32FC1 depth of the current frame (metres, NaN = none), or empty
  /// Precomputed detection of the current frame (VanishingPointDetector::detect on this frame's
  /// grey image, same intrinsics). When set, process() uses it as is and runs no detector of its
  /// own (gray is ignored); when empty, process() detects on gray (if any). Either way it is
  /// used only with filter.enabled and filter.vanishing_points.
  std::optional<VanishingPoint> detection;
};

/// A vanishing point found in a frame and what the filter did with it (published on LCM).
struct VanishingPointReport {
  VanishingPoint detection;
  VpUpdateResult update;
};

struct FilterOutput {
  PoseEstimate pose;  ///< filtered T_world_camera with its 6x6 covariance
  EkfPredictStatus predict_status = EkfPredictStatus::kOk;
  /// Set when an image or a precomputed detection was given and vanishing points are enabled
  /// (status says if one was found): the detection the filter used.
  std::optional<VanishingPoint> vanishing_point;
  /// Set when a vanishing point was found and handed to the EKF (only those supported by at least
  /// filter.min_update_lines lines are).
  std::optional<VpUpdateResult> update;
  /// Set when a depth image was given and surface axes are enabled.
  std::optional<SurfaceAxes> surface_axes;
  /// One result per axis handed to the EKF (in the order of surface_axes->axes).
  std::vector<VpUpdateResult> axis_updates;
};

class VanishingPointFilter {
 public:
  VanishingPointFilter(const FilterConfig& config, const CameraIntrinsics& intrinsics);

  FilterOutput process(const FilterInput& input);

  PoseEkf& ekf() { return ekf_; }
  const PoseEkf& ekf() const { return ekf_; }
  const VanishingPointDetector& detector() const { return detector_; }
  const SurfaceAxisDetector& axisDetector() const { return axis_detector_; }
  std::int64_t steps() const { return steps_; }

 private:
  FilterConfig config_;
  VanishingPointDetector detector_;
  SurfaceAxisDetector axis_detector_;
  PoseEkf ekf_;
  std::int64_t steps_ = 0;
};

}  // namespace slamd
