#include "slamd/filter/filter_config.hpp"

#include <limits>

namespace slamd {

VanishingPointConfig VanishingPointConfig::load(Config& config, const std::string& prefix) {
  VanishingPointConfig c;
  const auto key = [&prefix](const char* name) { return prefix + "." + name; };
  c.segment_detector = config.getChoice(key("segment_detector"), c.segment_detector, {"hough", "lsd"});
  c.image_scale = config.getDouble(key("image_scale"), c.image_scale, 0.1, 1.0);
  c.blur_kernel_px = config.getInt(key("blur_kernel_px"), c.blur_kernel_px, 0, 15);
  c.canny_low = config.getDouble(key("canny_low"), c.canny_low, 1.0, 1000.0);
  c.canny_high = config.getDouble(key("canny_high"), c.canny_high, 1.0, 1000.0);
  if (c.canny_low > c.canny_high) {
    throw ConfigError(key("canny_low") + " = " + std::to_string(c.canny_low) +
                      ": must not exceed " + key("canny_high") + " = " +
                      std::to_string(c.canny_high));
  }
  c.canny_aperture = config.getInt(key("canny_aperture"), c.canny_aperture, 3, 7);
  if (c.canny_aperture % 2 == 0) {
    throw ConfigError(key("canny_aperture") + " = " + std::to_string(c.canny_aperture) +
                      ": allowed values are 3, 5, 7");
  }
  c.hough_rho_px = config.getDouble(key("hough_rho_px"), c.hough_rho_px, 0.1, 10.0);
  c.hough_theta_deg = config.getDouble(key("hough_theta_deg"), c.hough_theta_deg, 0.1, 10.0);
  c.hough_threshold = config.getInt(key("hough_threshold"), c.hough_threshold, 1, 1000);
  c.min_line_length_px =
      config.getDouble(key("min_line_length_px"), c.min_line_length_px, 2.0, 2000.0);
  c.max_line_gap_px = config.getDouble(key("max_line_gap_px"), c.max_line_gap_px, 0.0, 100.0);
  c.subpixel_lines = config.getBool(key("subpixel_lines"), c.subpixel_lines);
  c.max_segments = config.getInt(key("max_segments"), c.max_segments, 2, 5000);
  c.reject_axis_parallel = config.getBool(key("reject_axis_parallel"), c.reject_axis_parallel);
  c.axis_parallel_angle_deg =
      config.getDouble(key("axis_parallel_angle_deg"), c.axis_parallel_angle_deg, 0.0, 45.0);
  c.ransac_iterations = config.getInt(key("ransac_iterations"), c.ransac_iterations, 1, 100000);
  c.inlier_angle_deg = config.getDouble(key("inlier_angle_deg"), c.inlier_angle_deg, 0.05, 20.0);
  c.min_supporting_lines =
      config.getInt(key("min_supporting_lines"), c.min_supporting_lines, 2, 1000);
  c.refine_iterations = config.getInt(key("refine_iterations"), c.refine_iterations, 1, 20);
  c.max_outside_fraction =
      config.getDouble(key("max_outside_fraction"), c.max_outside_fraction, 0.0, 100.0);
  c.min_pixel_sigma_px =
      config.getDouble(key("min_pixel_sigma_px"), c.min_pixel_sigma_px, 0.01, 100.0);
  c.seed = config.getInt(key("seed"), c.seed, 0, std::numeric_limits<int>::max());
  return c;
}

FilterConfig FilterConfig::load(Config& config) {
  FilterConfig c;
  c.enabled = config.getBool("filter.enabled", c.enabled);
  c.vanishing_points = config.getBool("filter.vanishing_points", c.vanishing_points);
  c.surface_axes = config.getBool("filter.surface_axes", c.surface_axes);
  c.translation_noise_m_per_sqrt_s = config.getDouble(
      "filter.translation_noise_m_per_sqrt_s", c.translation_noise_m_per_sqrt_s, 0.0, 10.0);
  c.rotation_noise_rad_per_sqrt_s = config.getDouble(
      "filter.rotation_noise_rad_per_sqrt_s", c.rotation_noise_rad_per_sqrt_s, 0.0, 10.0);
  c.odometry_covariance_scale = config.getDouble("filter.odometry_covariance_scale",
                                                 c.odometry_covariance_scale, 0.01, 1e4);
  c.fallback_translation_sigma_m = config.getDouble(
      "filter.fallback_translation_sigma_m", c.fallback_translation_sigma_m, 1e-6, 10.0);
  c.fallback_rotation_sigma_rad = config.getDouble("filter.fallback_rotation_sigma_rad",
                                                   c.fallback_rotation_sigma_rad, 1e-6, 3.0);
  c.max_angular_rate_radps =
      config.getDouble("filter.max_angular_rate_radps", c.max_angular_rate_radps, 0.01, 100.0);
  c.max_speed_mps = config.getDouble("filter.max_speed_mps", c.max_speed_mps, 0.01, 100.0);
  c.gate_chi2 = config.getDouble("filter.gate_chi2", c.gate_chi2, 0.1, 1000.0);
  c.measurement_noise_scale = config.getDouble("filter.measurement_noise_scale",
                                               c.measurement_noise_scale, 0.01, 1e4);
  c.landmark_init_frames =
      config.getInt("filter.landmark_init_frames", c.landmark_init_frames, 1, 100);
  c.landmark_init_angle_deg = config.getDouble("filter.landmark_init_angle_deg",
                                               c.landmark_init_angle_deg, 0.01, 45.0);
  c.landmark_min_separation_deg = config.getDouble("filter.landmark_min_separation_deg",
                                                   c.landmark_min_separation_deg, 0.0, 90.0);
  c.landmark_probation =
      config.getInt("filter.landmark_probation", c.landmark_probation, 0, 1000);
  c.landmark_window = config.getInt("filter.landmark_window", c.landmark_window, 1, 1000);
  c.landmark_consistency_chi2 = config.getDouble("filter.landmark_consistency_chi2",
                                                 c.landmark_consistency_chi2, 0.1, 1000.0);
  c.landmark_retry_calls =
      config.getInt("filter.landmark_retry_calls", c.landmark_retry_calls, 0, 1000000);
  c.reanchor_detections =
      config.getInt("filter.reanchor_detections", c.reanchor_detections, 0, 1000);
  c.reanchor_min_updates =
      config.getInt("filter.reanchor_min_updates", c.reanchor_min_updates, 1, 1000000);
  c.min_update_lines = config.getInt("filter.min_update_lines", c.min_update_lines, 2, 1000);
  c.max_landmarks = config.getInt("filter.max_landmarks", c.max_landmarks, 0, 32);
  c.axes = SurfaceAxesConfig::load(config);
  c.initial_translation_sigma_m = config.getDouble("filter.initial_translation_sigma_m",
                                                   c.initial_translation_sigma_m, 0.0, 100.0);
  c.initial_rotation_sigma_rad = config.getDouble("filter.initial_rotation_sigma_rad",
                                                  c.initial_rotation_sigma_rad, 0.0, 10.0);
  c.max_dt_s = config.getDouble("filter.max_dt_s", c.max_dt_s, 0.001, 3600.0);
  c.vp = VanishingPointConfig::load(config, "filter.vp");
  return c;
}

}  // namespace slamd
