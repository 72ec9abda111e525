#include "slamd/filter/filter_config.hpp"

#include <limits>

namespace slamd {

namespace {

const EnumNames<std::string> kSegmentDetectorNames = {
    {"hough", "hough", "probabilistic Hough on Canny edges (paper 002)"},
    {"lsd", "lsd", "OpenCV's line segment detector"},
};

}  // namespace

const ConfigSchema<VanishingPointConfig>& VanishingPointConfig::schema() {
  using C = VanishingPointConfig;
  static const auto table =
      ConfigSchema<C>("filter.vp")
          .choice("segment_detector", &C::segment_detector, kSegmentDetectorNames,
                  "how line segments are found")
          .number("image_scale", &C::image_scale, 0.1, 1.0, "",
                  "segments are extracted from the image resized by this factor (area averaging) "
                  "and scaled back to full-resolution pixels")
          .number("blur_kernel_px", &C::blur_kernel_px, 0, 15, "px (resized image)",
                  "Gaussian blur before Canny; 0 or 1 = none, even sizes are rounded up to odd; "
                  "use 5 with image_scale 1")
          .number("canny_low", &C::canny_low, 1.0, 1000.0, "grey levels",
                  "Canny lower hysteresis threshold; <= canny_high")
          .number("canny_high", &C::canny_high, 1.0, 1000.0, "grey levels",
                  "Canny upper hysteresis threshold")
          .number("canny_aperture", &C::canny_aperture, 3, 7, "px",
                  "Sobel aperture of Canny: 3, 5 or 7")
          .number("hough_rho_px", &C::hough_rho_px, 0.1, 10.0, "px",
                  "distance resolution of the Hough space")
          .number("hough_theta_deg", &C::hough_theta_deg, 0.1, 10.0, "deg",
                  "angle resolution of the Hough space")
          .number("hough_threshold", &C::hough_threshold, 1, 1000, "votes",
                  "accumulator threshold at full resolution (multiplied by image_scale)")
          .number("min_line_length_px", &C::min_line_length_px, 2.0, 2000.0, "px",
                  "shorter segments are dropped")
          .number("max_line_gap_px", &C::max_line_gap_px, 0.0, 100.0, "px",
                  "gap bridged inside one Hough segment")
          .flag("subpixel_lines", &C::subpixel_lines,
                "refit every segment's line to sub-pixel edge positions of the full-resolution "
                "grey image (contrast-weighted total least squares)")
          .number("max_segments", &C::max_segments, 2, 5000, "",
                  "only the longest segments are kept")
          .flag("reject_axis_parallel", &C::reject_axis_parallel,
                "drop segments nearly parallel to the image axes")
          .number("axis_parallel_angle_deg", &C::axis_parallel_angle_deg, 0.0, 45.0, "deg",
                  "\"nearly parallel\" tolerance")
          .number("ransac_iterations", &C::ransac_iterations, 1, 100000, "",
                  "random line pairs tried (all pairs when there are fewer)")
          .number("inlier_angle_deg", &C::inlier_angle_deg, 0.05, 20.0, "deg",
                  "a segment supports a point when the angle between it and the ray from its "
                  "midpoint to the point is below")
          .number("min_supporting_lines", &C::min_supporting_lines, 2, 1000, "",
                  "fewer inliers = no vanishing point")
          .number("refine_iterations", &C::refine_iterations, 1, 20, "",
                  "least-squares refinements (inliers re-chosen around each refined point)")
          .number("max_outside_fraction", &C::max_outside_fraction, 0.0, 100.0,
                  "fraction of image size",
                  "a point more than this fraction of the width (height) outside the image is "
                  "rejected as too far (0.25: about 37 degrees off axis for a Kinect)")
          .number("min_pixel_sigma_px", &C::min_pixel_sigma_px, 0.01, 100.0, "px",
                  "floor added (squared) to both axes of the residual covariance")
          .number("seed", &C::seed, 0, std::numeric_limits<int>::max(), "",
                  "RANSAC random seed (results are reproducible per image)");
  return table;
}

VanishingPointConfig VanishingPointConfig::load(Config& config) {
  VanishingPointConfig c;
  schema().load(config, c);
  if (c.canny_low > c.canny_high) {
    throw ConfigError("filter.vp.canny_low = " + std::to_string(c.canny_low) +
                      ": must not exceed filter.vp.canny_high = " + std::to_string(c.canny_high));
  }
  if (c.canny_aperture % 2 == 0) {
    throw ConfigError("filter.vp.canny_aperture = " + std::to_string(c.canny_aperture) +
                      ": allowed values are 3, 5, 7");
  }
  return c;
}

const ConfigSchema<FilterConfig>& FilterConfig::schema() {
  using C = FilterConfig;
  static const auto table =
      ConfigSchema<C>("filter")
          .flag("enabled", &C::enabled, "false passes odometry through (poses chained, no EKF)")
          .flag("vanishing_points", &C::vanishing_points,
                "detect vanishing points and use them as updates")
          .flag("surface_axes", &C::surface_axes,
                "detect the dominant plane axes of the depth image (filter.axes.*) and use them "
                "as updates of the same direction landmarks")
          .number("translation_noise_m_per_sqrt_s", &C::translation_noise_m_per_sqrt_s, 0.0, 10.0,
                  "m/sqrt(s)",
                  "process noise added to each prediction on top of the odometry covariance")
          .number("rotation_noise_rad_per_sqrt_s", &C::rotation_noise_rad_per_sqrt_s, 0.0, 10.0,
                  "rad/sqrt(s)", "as above for the rotation (camera frame, right perturbation)")
          .number("odometry_covariance_scale", &C::odometry_covariance_scale, 0.01, 1e4, "",
                  "multiplies each odometry covariance")
          .number("fallback_translation_sigma_m", &C::fallback_translation_sigma_m, 1e-6, 10.0, "m",
                  "translation sigma of an odometry increment whose own covariance is NaN or not "
                  "positive semi-definite (counted)")
          .number("fallback_rotation_sigma_rad", &C::fallback_rotation_sigma_rad, 1e-6, 3.0, "rad",
                  "the same for the rotation")
          .number("gate_chi2", &C::gate_chi2, 0.1, 1000.0, "",
                  "Mahalanobis gate on the 2-DoF vanishing-point innovation")
          .number("measurement_noise_scale", &C::measurement_noise_scale, 0.01, 1e4, "",
                  "multiplies each vanishing-point pixel covariance")
          .number("landmark_init_frames", &C::landmark_init_frames, 1, 100, "detections",
                  "consecutive unassociated detections of one world direction before a new "
                  "landmark is created")
          .number("landmark_init_angle_deg", &C::landmark_init_angle_deg, 0.01, 45.0, "deg",
                  "world directions closer than this are \"the same\" while a candidate is "
                  "confirmed")
          .number("landmark_min_separation_deg", &C::landmark_min_separation_deg, 0.0, 90.0, "deg",
                  "a candidate closer than this to an existing landmark is never created")
          .number("landmark_probation", &C::landmark_probation, 0, 1000, "detections",
                  "a new landmark first only tests this many detections, then becomes active if "
                  "consistent, otherwise is retired; 0 = active at once")
          .number("landmark_window", &C::landmark_window, 1, 1000, "detections",
                  "an active landmark is retired when its last this many detections are "
                  "inconsistent")
          .number("landmark_consistency_chi2", &C::landmark_consistency_chi2, 0.1, 1000.0, "",
                  "a landmark is consistent while the median NIS of its recent detections stays "
                  "at or below this")
          .number("landmark_retry_calls", &C::landmark_retry_calls, 0, 1000000, "vanishing points",
                  "a retired landmark's direction cannot start a new landmark for this many "
                  "vanishing points")
          .number("reanchor_detections", &C::reanchor_detections, 0, 1000, "detections",
                  "gated, mutually consistent detections of an established landmark that "
                  "re-anchor the pose after an odometry jump; 0 disables")
          .number("reanchor_min_updates", &C::reanchor_min_updates, 1, 1000000, "updates",
                  "accepted updates that make a landmark established")
          .number("max_correction_rate_degps", &C::max_correction_rate_degps, 0.0, 10000.0, "deg/s",
                  "a re-anchoring turns the pose at most this fast; a larger correction is "
                  "spread over several frames; 0 = no limit")
          .number("max_correction_speed_mps", &C::max_correction_speed_mps, 0.0, 1000.0, "m/s",
                  "a re-anchoring moves the pose at most this fast; a larger correction is "
                  "spread over several frames; 0 = no limit")
          .number("min_update_lines", &C::min_update_lines, 2, 1000, "lines",
                  "a vanishing point supported by fewer lines is reported but not given to the "
                  "EKF")
          .number("max_landmarks", &C::max_landmarks, 0, 32, "",
                  "direction landmarks kept in the state")
          .number("initial_translation_sigma_m", &C::initial_translation_sigma_m, 0.0, 100.0, "m",
                  "initial position uncertainty")
          .number("initial_rotation_sigma_rad", &C::initial_rotation_sigma_rad, 0.0, 10.0, "rad",
                  "initial rotation uncertainty")
          .number("max_dt_s", &C::max_dt_s, 0.001, 3600.0, "s",
                  "dt used for process noise is clamped here");
  return table;
}

const ConfigSchema<PlaneOdometryConfig>& PlaneOdometryConfig::schema() {
  using C = PlaneOdometryConfig;
  static const auto table =
      ConfigSchema<C>("filter.planes")
          .flag("enabled", &C::enabled,
                "the corridor mode: where features run out, frames are segmented into planes (own "
                "thread) and plane ICP against the frame tracking measured from is fused with "
                "tracking's measurement (docs/planes.md)")
          .number("corridor_min_inliers", &C::corridor_min_inliers, 0, 100000, "inliers",
                  "a frame tracked with fewer inliers (or not measured by features) switches "
                  "the corridor mode on")
          .number("corridor_exit_frames", &C::corridor_exit_frames, 1, 100000, "frames",
                  "consecutive frames with enough inliers that switch it off again")
          .number("information_scale", &C::information_scale, 1e-6, 1e6, "",
                  "multiplies plane ICP's information matrix (its samples are not independent)")
          .number("gate_probability", &C::gate_probability, 0.95, 0.999, "",
                  "plane and tracking increments that disagree beyond this chi-square quantile "
                  "are not fused (0.95, 0.99 or 0.999)")
          .number("points_per_plane", &C::points_per_plane, 10, 100000, "points",
                  "points drawn on each plane for ICP (paper 000)")
          .flag("fuse_rotation", &C::fuse_rotation,
                "also fuse the rotation the planes measure (off: their translation only, the "
                "rotation marginalised out)");
  return table;
}

PlaneOdometryConfig PlaneOdometryConfig::load(Config& config) {
  PlaneOdometryConfig c;
  schema().load(config, c);
  return c;
}

FilterConfig FilterConfig::load(Config& config) {
  FilterConfig c;
  schema().load(config, c);
  c.axes = SurfaceAxesConfig::load(config);
  c.vp = VanishingPointConfig::load(config);
  c.planes = PlaneOdometryConfig::load(config);
  c.motion_limits = MotionLimits::load(config);
  return c;
}

}  // namespace slamd
