#pragma once
// Configuration of the filter area (the `filter.*` keys): the vanishing-point detector
// (`filter.vp.*`), the surface-axis detector (`filter.axes.*`) and the pose EKF. load() throws
// ConfigError naming the key when a value is out of range or of the wrong type.

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"
#include "slamd/common/motion_limits.hpp"
#include "slamd/filter/surface_axes.hpp"

namespace slamd {

// Each key's type, default, range, unit and doc: its row in filter_config.cpp (its one
// declaration), or `slamd --describe-config filter`. The members' comments give only what a row's
// doc does not: the reasons behind defaults.

/// Vanishing-point detector options, keys `filter.vp.*`.
struct VanishingPointConfig {
  std::string segment_detector = "hough";
  /// 0.5 quarters the Hough cost; pixel-valued options stay in full-resolution pixels.
  double image_scale = 0.5;
  int blur_kernel_px = 0;
  double canny_low = 40.0;
  double canny_high = 120.0;
  int canny_aperture = 3;
  double hough_rho_px = 1.0;
  /// The Hough cost is proportional to the number of angles, and segments are refitted to their
  /// edge pixels afterwards, so 2 degrees loses nothing measurable against 1 and saves a third of
  /// the filter CPU on TUM fr1/xyz.
  double hough_theta_deg = 2.0;
  int hough_threshold = 40;
  double min_line_length_px = 30.0;
  double max_line_gap_px = 5.0;
  /// Off, lines run through the centres of reduced-resolution edge pixels, which biased the
  /// corridor's vanishing point by 0.3 px.
  bool subpixel_lines = true;
  int max_segments = 150;
  bool reject_axis_parallel = true;  ///< door frames and cross-corridor edges (paper 002)
  double axis_parallel_angle_deg = 5.0;
  int ransac_iterations = 300;
  double inlier_angle_deg = 1.5;
  int min_supporting_lines = 5;
  int refine_iterations = 3;
  /// Far-off points are extrapolated from lines that converge at grazing angles: with 0.5, on TUM
  /// fr1/xyz a desk direction at x ~ 850 px became a landmark and cost 11% ATE. A corridor's
  /// point stays in the image while the camera looks along it.
  double max_outside_fraction = 0.25;
  double min_pixel_sigma_px = 0.5;
  int seed = 42;

  /// The `filter.vp.*` keys.
  static const ConfigSchema<VanishingPointConfig>& schema();
  /// Reads `filter.vp.*`; throws ConfigError.
  static VanishingPointConfig load(Config& config);
};

/// The corridor mode, keys `filter.planes.*` (issue 23 item 4): where features run out, frames
/// are segmented into planes (on their own thread), and plane ICP against the frame tracking
/// measured from (planes::registerPlanes, on the filter thread) is fused with tracking's
/// measurement by information before the EKF's prediction (filter/motion_fusion.hpp,
/// app/pose_estimator.hpp).
struct PlaneOdometryConfig {
  /// On: the mode only comes on where features run out, and there planes measure what the few
  /// features left measure worst (docs/planes.md has the held-out corridors).
  bool enabled = true;
  /// Below this many inliers a frame has "run out of features"; the keyframe rule's
  /// few-inlier threshold, so fr1/xyz and textured corridors (hundreds) hardly ever switch the
  /// mode on.
  int corridor_min_inliers = 50;
  int corridor_exit_frames = 30;
  /// Plane ICP takes its samples as independent, so its information overstates what it knows.
  double information_scale = 0.1;
  double gate_probability = 0.999;
  int points_per_plane = 200;
  /// On: two walls' normals fix the rotation wherever the mode is on, where the few features
  /// left measure it worst (up to a degree a frame facing a corridor's end). Off: only the
  /// translation is fused, the rotation marginalised out; a door that grows into its wall's
  /// plane tilts it (docs/planes.md), but against the reference that bias is the same in every
  /// frame and does not add up.
  bool fuse_rotation = true;

  static const ConfigSchema<PlaneOdometryConfig>& schema();
  static PlaneOdometryConfig load(Config& config);
};

/// Pose EKF and filter-stage options, keys `filter.*`.
struct FilterConfig {
  bool enabled = true;
  bool vanishing_points = true;
  /// Off by default: on TUM fr1/xyz (a desk, real Kinect depth) most axes are gated, the few
  /// accepted ones cost 5% ATE, and detection adds about 1.3 ms per frame on the filter thread;
  /// on a rendered corridor they make the roll observable.
  bool surface_axes = false;
  double translation_noise_m_per_sqrt_s = 0.002;  ///< variance = sigma^2 * dt
  double rotation_noise_rad_per_sqrt_s = 0.001;
  double odometry_covariance_scale = 1.0;  ///< odometry front ends are often over-confident
  double fallback_translation_sigma_m = 0.05;
  double fallback_rotation_sigma_rad = 0.02;
  /// A lost frame's "unknown" covariance (10 rad sigma) would otherwise leave the rotation about
  /// the vanishing direction, which no vanishing point observes, free to wander by degrees as
  /// later updates relinearise. Ordinary increments are far below the cap.
  /// filter.max_angular_rate_radps, filter.max_speed_mps (MotionLimits' schema rows).
  MotionLimits motion_limits;
  double gate_chi2 = 5.99;  ///< 95% of chi-square with 2 DoF
  double measurement_noise_scale = 1.0;
  int landmark_init_frames = 3;
  double landmark_init_angle_deg = 2.0;
  double landmark_min_separation_deg = 20.0;
  /// 99.9% of chi-square with 2 DoF; a consistent landmark's median NIS is ~1.4. Looser than
  /// gate_chi2 because successive innovations are correlated (the same odometry drift), so a
  /// consistent landmark can stay a little above the gate for a few frames, while a wrong one
  /// lands far above most of the time.
  double landmark_consistency_chi2 = 13.82;
  int landmark_probation = 10;
  int landmark_window = 60;
  int landmark_retry_calls = 150;
  /// Re-anchoring after an odometry jump (pose_ekf.hpp, "Re-anchoring"): when an established
  /// landmark has its last reanchor_detections vanishing points gated and their innovations agree
  /// with each other, the pose has jumped, not the direction. The pose covariance is widened by
  /// the jump and the detection applied; without it the landmark was gated until retired and a
  /// new one was created at the wrong pose.
  int reanchor_detections = 5;
  int reanchor_min_updates = 100;
  /// How fast a re-anchoring may move the pose (pose_ekf.hpp, "Spread corrections"): a larger
  /// correction is applied over several frames with a reduced gain. At 30 Hz, 10 deg/s and
  /// 0.1 m/s are 0.33 degree and 3.3 mm per frame: a published pose that a controller
  /// differentiates never jumps by a re-anchoring's degree or two. 0 = no limit.
  double max_correction_rate_degps = 10.0;
  double max_correction_speed_mps = 0.1;
  /// Corridors give 15-40 supporting lines; the short, few lines of cluttered scenes (a desk:
  /// 5-10) meet at points that scatter by degrees.
  int min_update_lines = 12;
  int max_landmarks = 4;                      ///< a Manhattan world's 3 axes, plus one on probation
  double initial_translation_sigma_m = 1e-6;  ///< the world frame is the first camera frame
  double initial_rotation_sigma_rad = 1e-6;
  double max_dt_s = 5.0;

  VanishingPointConfig vp;
  SurfaceAxesConfig axes;
  PlaneOdometryConfig planes;

  /// The `filter.*` keys of the EKF (vp and axes have their own tables).
  static const ConfigSchema<FilterConfig>& schema();
  /// Reads `filter.*`, `filter.vp.*`, `filter.axes.*` and `filter.planes.*`; throws ConfigError.
  static FilterConfig load(Config& config);
};

}  // namespace slamd
