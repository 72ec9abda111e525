#pragma once
// Configuration of the filter area (the `filter.*` keys): the vanishing-point detector
// (`filter.vp.*`) and the pose EKF. Every option below lists its type, default, allowed range and
// unit; load() throws ConfigError naming the key when a value is out of range or of the wrong type.

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/filter/surface_axes.hpp"

namespace slamd {

/// Vanishing-point detector options, keys `filter.vp.*`.
struct VanishingPointConfig {
  /// `segment_detector` (choice hough|lsd, default hough): probabilistic Hough on Canny edges
  /// (paper 002) or OpenCV's line segment detector.
  std::string segment_detector = "hough";
  /// `image_scale` (double, default 0.5, 0.1..1, dimensionless): segments are extracted from the
  /// image resized by this factor (area averaging) and scaled back to full-resolution pixels; the
  /// pixel-valued options below stay in full-resolution pixels. 0.5 quarters the Hough cost.
  double image_scale = 0.5;
  /// `blur_kernel_px` (int, default 0, 0..15, pixels of the resized image): Gaussian blur before
  /// Canny; 0 or 1 = none (the area-averaging resize already smooths), even values are rounded up
  /// to the next odd size. Use 5 with image_scale 1.
  int blur_kernel_px = 0;
  /// `canny_low`, `canny_high` (double, defaults 40 / 120, 1..1000, grey levels): Canny hysteresis
  /// thresholds; canny_low must not exceed canny_high.
  double canny_low = 40.0;
  double canny_high = 120.0;
  /// `canny_aperture` (int, default 3, one of 3, 5, 7): Sobel aperture of Canny.
  int canny_aperture = 3;
  /// `hough_rho_px` (double, default 1, 0.1..10, pixels): distance resolution of the Hough space.
  double hough_rho_px = 1.0;
  /// `hough_theta_deg` (double, default 2, 0.1..10, degrees): angle resolution of the Hough space.
  /// The Hough transform's cost is proportional to the number of angles, and the segments are
  /// refitted to their edge pixels afterwards, so 2 degrees loses nothing measurable: TUM fr1/xyz
  /// filter CPU median 5.9 -> 3.9 ms per frame (quiet machine), rendered low-texture corridor
  /// (30 m walk, 5 seeds) end yaw / pitch errors within the seed-to-seed spread of 1 degree's.
  double hough_theta_deg = 2.0;
  /// `hough_threshold` (int, default 40, 1..1000, votes at full resolution; multiplied by
  /// image_scale): accumulator threshold.
  int hough_threshold = 40;
  /// `min_line_length_px` (double, default 30, 2..2000, pixels): shorter segments are dropped.
  double min_line_length_px = 30.0;
  /// `max_line_gap_px` (double, default 5, 0..100, pixels): gap bridged inside one Hough segment.
  double max_line_gap_px = 5.0;
  /// `subpixel_lines` (bool, default true): refit every segment's line to sub-pixel edge
  /// positions of the full-resolution grey image (grey-level differences across the line,
  /// parabolic peak, contrast-weighted total least squares). Off, lines run through the centres of
  /// reduced-resolution edge pixels, which biased the corridor's vanishing point by 0.3 px.
  bool subpixel_lines = true;
  /// `max_segments` (int, default 150, 2..5000): only the longest segments are kept.
  int max_segments = 150;
  /// `reject_axis_parallel` (bool, default true): drop segments nearly parallel to the image axes
  /// (paper 002: door frames and cross-corridor edges do not meet at the corridor's point).
  bool reject_axis_parallel = true;
  /// `axis_parallel_angle_deg` (double, default 5, 0..45, degrees): "nearly parallel" tolerance.
  double axis_parallel_angle_deg = 5.0;
  /// `ransac_iterations` (int, default 300, 1..100000): random line pairs tried; all pairs are
  /// tried instead when there are fewer.
  int ransac_iterations = 300;
  /// `inlier_angle_deg` (double, default 1.5, 0.05..20, degrees): a segment supports a candidate
  /// point when the angle between the segment and the ray from its midpoint to the point is below.
  double inlier_angle_deg = 1.5;
  /// `min_supporting_lines` (int, default 5, 2..1000): fewer inliers = no vanishing point.
  int min_supporting_lines = 5;
  /// `refine_iterations` (int, default 3, 1..20): least-squares refinements (inliers re-chosen
  /// around each refined point).
  int refine_iterations = 3;
  /// `max_outside_fraction` (double, default 0.25, 0..100, fraction of the image size): a point
  /// more than this fraction of the width (height) outside the image is rejected as too far (at
  /// 0.25, about 37 degrees off the optical axis for a Kinect). Far-off points are extrapolated
  /// from lines that converge at grazing angles: with 0.5, on TUM fr1/xyz a desk direction at
  /// x ~ 850 px (13-21 of 55-77 lines, 6-13 px sigma) became a landmark and its 4 updates cost 11%
  /// ATE. A corridor's point stays in the image while the camera looks along it.
  double max_outside_fraction = 0.25;
  /// `min_pixel_sigma_px` (double, default 0.5, 0.01..100, pixels): floor added (squared) to both
  /// axes of the residual covariance, so few near-perfect lines never claim sub-floor accuracy.
  double min_pixel_sigma_px = 0.5;
  /// `seed` (int, default 42, 0..2^31-1): RANSAC random seed (results are reproducible per image).
  int seed = 42;

  /// Reads `<prefix>.*` (default prefix "filter.vp"); throws ConfigError.
  static VanishingPointConfig load(Config& config, const std::string& prefix = "filter.vp");
};

/// Pose EKF and filter-stage options, keys `filter.*`.
struct FilterConfig {
  /// `enabled` (bool, default true): false passes odometry through (poses chained, no EKF).
  bool enabled = true;
  /// `vanishing_points` (bool, default true): detect vanishing points and use them as updates.
  bool vanishing_points = true;
  /// `surface_axes` (bool, default false): detect the dominant plane axes of the depth image
  /// (floor, walls: Manhattan directions from depth normals, `filter.axes.*`) and use them as
  /// updates of the same direction landmarks; they make the roll about a corridor observable
  /// (rendered corridor: roll RMS error 0.085 -> 0.032 deg). Off by default: on TUM fr1/xyz (a
  /// desk, real Kinect depth) most axes are gated, the few accepted ones cost 5% ATE, and
  /// detection adds about 1.3 ms per frame on the filter thread.
  bool surface_axes = false;
  /// `translation_noise_m_per_sqrt_s` (double, default 0.002, 0..10, m/sqrt(s)): process noise
  /// added to each prediction on top of the odometry covariance, variance = sigma^2 * dt.
  double translation_noise_m_per_sqrt_s = 0.002;
  /// `rotation_noise_rad_per_sqrt_s` (double, default 0.001, 0..10, rad/sqrt(s)): as above for
  /// the rotation (camera frame, right perturbation).
  double rotation_noise_rad_per_sqrt_s = 0.001;
  /// `odometry_covariance_scale` (double, default 1, 0.01..1e4): multiplies each odometry
  /// covariance (odometry front ends are often over-confident).
  double odometry_covariance_scale = 1.0;
  /// `fallback_translation_sigma_m` (double, default 0.05, 1e-6..10, m) and
  /// `fallback_rotation_sigma_rad` (double, default 0.02, 1e-6..3, rad): covariance used for an
  /// odometry increment whose own covariance is NaN or not positive semi-definite (counted).
  double fallback_translation_sigma_m = 0.05;
  double fallback_rotation_sigma_rad = 0.02;
  /// `max_angular_rate_radps` (double, default 4, 0.01..100, rad/s) and `max_speed_mps` (double,
  /// default 3, 0.01..100, m/s): how fast the camera can turn and move. An odometry increment's
  /// variance is capped at (limit * dt)^2 per axis (rows and columns scaled, correlations kept):
  /// a lost frame's "unknown" covariance (10 rad sigma) would otherwise leave the rotation about
  /// the vanishing direction, which no vanishing point observes, free to wander by degrees as
  /// later updates relinearise. Ordinary increments are far below the cap.
  double max_angular_rate_radps = 4.0;
  double max_speed_mps = 3.0;
  /// `gate_chi2` (double, default 5.99, 0.1..1000, dimensionless): Mahalanobis gate on the
  /// 2-DoF vanishing-point innovation (5.99 = 95% of chi-square with 2 DoF).
  double gate_chi2 = 5.99;
  /// `measurement_noise_scale` (double, default 1, 0.01..1e4): multiplies each vanishing-point
  /// pixel covariance before it is used.
  double measurement_noise_scale = 1.0;
  /// `landmark_init_frames` (int, default 3, 1..100): consecutive unassociated detections of the
  /// same world direction needed before a new landmark is created.
  int landmark_init_frames = 3;
  /// `landmark_init_angle_deg` (double, default 2, 0.01..45, degrees): world directions closer than
  /// this count as "the same" while a candidate landmark is being confirmed.
  double landmark_init_angle_deg = 2.0;
  /// `landmark_min_separation_deg` (double, default 20, 0..90, degrees): a candidate closer than
  /// this to an existing landmark's axis is never created (a gated detection of a known direction).
  double landmark_min_separation_deg = 20.0;
  /// `landmark_consistency_chi2` (double, default 13.82, 0.1..1000, dimensionless): a landmark is
  /// consistent while the median NIS of the recent detections of its direction (within
  /// landmark_min_separation_deg, gated or not) stays at or below this (13.82 = 99.9% of
  /// chi-square with 2 DoF; the median of a consistent landmark's NIS is ~1.4). The median ignores
  /// occasional wrong detections; it is looser than gate_chi2 because successive innovations are
  /// correlated (the same odometry drift), so a consistent landmark can stay a little above the
  /// gate for a few frames, while a wrong one lands far above most of the time.
  double landmark_consistency_chi2 = 13.82;
  /// `landmark_probation` (int, default 10, 0..1000, detections): a landmark created from
  /// detections (not by addLandmark) first only tests this many detections of its direction
  /// without updating anything; then it becomes active (updates the pose) if consistent, otherwise
  /// it is retired. 0 = active at once.
  int landmark_probation = 10;
  /// `landmark_window` (int, default 60, 1..1000, detections): an active landmark is retired when
  /// the last landmark_window detections of its direction are inconsistent (it is not a fixed
  /// direction, or its detections are far worse than their covariance says).
  int landmark_window = 60;
  /// `landmark_retry_calls` (int, default 150, 0..1000000, vanishing points): after a landmark is
  /// retired its direction cannot start a new landmark for this many vanishing points (5 s at
  /// 30 Hz); a later one goes through probation again.
  int landmark_retry_calls = 150;
  /// `reanchor_detections` (int, default 5, 0..1000, detections; 0 disables) and
  /// `reanchor_min_updates` (int, default 100, 1..1000000, accepted updates): re-anchoring after an
  /// odometry jump. When an established landmark (at least reanchor_min_updates accepted updates)
  /// has its last reanchor_detections vanishing points gated, and their innovations agree with
  /// each other (each within gate_chi2 of their mean), the pose has jumped, not the direction: one
  /// bad odometry increment with an over-confident covariance. The pose covariance is widened by
  /// the jump (sigma = twice the mean innovation's angle, in the shape of the latest odometry
  /// increment's noise, the rotation about the direction left out) and the detection is applied
  /// (pose_ekf.hpp, "Re-anchoring"). Without it the landmark was gated until
  /// retired and a new one was created at the wrong pose (rendered corridor, texture 0.02, seed
  /// 45, fovis: a 0.4 deg jump at frame 696 stayed in the filtered pose to the end).
  int reanchor_detections = 5;
  int reanchor_min_updates = 100;
  /// `min_update_lines` (int, default 12, 2..1000): a vanishing point supported by fewer lines is
  /// reported but not given to the EKF. Corridors give 15-40 supporting lines; the short, few
  /// lines of cluttered scenes (a desk: 5-10) meet at points that scatter by degrees.
  int min_update_lines = 12;
  /// `max_landmarks` (int, default 4, 0..32): direction landmarks kept in the state (a Manhattan
  /// world has 3 axes; one more leaves room for a landmark on probation).
  int max_landmarks = 4;
  /// `initial_translation_sigma_m` (double, default 1e-6, 0..100, m) and
  /// `initial_rotation_sigma_rad` (double, default 1e-6, 0..10, rad): initial pose uncertainty
  /// (the world frame is the first camera frame).
  double initial_translation_sigma_m = 1e-6;
  double initial_rotation_sigma_rad = 1e-6;
  /// `max_dt_s` (double, default 5, 0.001..3600, s): dt used for process noise is clamped here.
  double max_dt_s = 5.0;

  VanishingPointConfig vp;
  SurfaceAxesConfig axes;

  /// Reads `filter.*`, `filter.vp.*` and `filter.axes.*`; throws ConfigError.
  static FilterConfig load(Config& config);
};

}  // namespace slamd
