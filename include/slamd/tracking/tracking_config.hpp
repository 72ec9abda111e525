#pragma once
// TrackingConfig: every option of visual odometry, read from the `tracking.*` keys.
//
//   Config config = Config::fromFile("config/tum_fr1.yaml");
//   TrackingConfig tracking = TrackingConfig::load(config);   // throws ConfigError when invalid

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"
#include "slamd/common/motion_limits.hpp"

namespace slamd {

/// Feature front end used by VisualOdometry (key tracking.frontend).
enum class FrontEndType { kOrb, kSift, kFovis };

const char* frontEndName(FrontEndType type);

// Each key's type, default, range, unit and doc: tracking_config.cpp (its one declaration), or
// `slamd --describe-config tracking`.
struct TrackingConfig {
  FrontEndType frontend = FrontEndType::kOrb;

  // --- Features -------------------------------------------------------------------------------
  int max_features = 1000;
  int grid_cols = 8;  ///< spatial buckets: each keeps max_features / (cols * rows) features
  int grid_rows = 6;
  int orb_levels = 3;
  int orb_fast_threshold = 20;
  bool subpixel = true;
  bool patch_refinement = true;
  double align_blur_sigma_px = 1.0;
  bool undistort = true;
  double min_depth_m = 0.3;
  double max_depth_m = 5.0;
  bool depth_time_correction = true;

  // --- Matching -------------------------------------------------------------------------------
  double match_ratio = 0.8;
  int max_descriptor_distance = 64;
  double search_radius_px = 20.0;
  double refine_search_radius_px = 4.0;
  int min_guided_matches = 60;

  /// How inliers are found before refinement.
  enum class OutlierRejection { kAuto, kRansac, kClique };
  OutlierRejection outlier_rejection = OutlierRejection::kAuto;
  bool useClique() const {
    return outlier_rejection == OutlierRejection::kClique ||
           (outlier_rejection == OutlierRejection::kAuto && frontend == FrontEndType::kFovis);
  }

  enum class Switch { kAuto, kOn, kOff };
  Switch rotation_prior = Switch::kAuto;
  bool useRotationPrior() const {
    return rotation_prior == Switch::kOn ||
           (rotation_prior == Switch::kAuto && frontend == FrontEndType::kFovis);
  }

  // --- Motion estimation ----------------------------------------------------------------------
  int ransac_iterations = 200;
  double inlier_threshold_px = 3.0;
  int min_inliers = 15;
  int min_features = 20;
  int max_iterations = 10;
  double pixel_sigma_px = 1.0;
  double depth_sigma_coeff = 0.0015;  ///< sigma_z = depth_sigma_coeff * z^2 (Kinect-type sensors)
  bool estimate_noise_scale = true;
  double huber_k = 1.5;

  int joint_references = -1;  ///< -1 = auto, see jointReferences()
  int jointReferences() const {
    if (joint_references >= 0) return joint_references;
    return frontend == FrontEndType::kFovis ? 0 : 2;
  }
  int joint_max_matches = 150;

  // --- Tracking against the local map (local_map.hpp) -----------------------------------------
  /// After the keyframe, match the landmarks of covisible keyframes by projection and refine
  /// against all of them (instead of joint_references whole keyframes).
  bool local_map = true;
  int local_map_keyframes = 10;   ///< covisible keyframes whose landmarks are searched
  int local_map_min_shared = 10;  ///< landmarks a keyframe must share to be covisible
  int local_map_max_matches = 300;
  /// A frame measured against its keyframe with fewer than keyframe_min_inliers inliers is refined
  /// jointly with its matches against the previous frame (held at its pose). Far from the keyframe
  /// in a fast turn, or facing one wall, few matches leave the estimate in a valley (a yaw and a
  /// sideways slide look alike on one plane); the previous frame, a frame's motion away, shares
  /// more of the view, and the frame would otherwise become a keyframe with that error.
  bool few_inliers_previous_frame = true;
  /// Such a frame (fewer than keyframe_min_inliers inliers, against its keyframe or the previous
  /// frame) is also aligned densely against the previous measured frame, with the feature estimate
  /// and its covariance as the prior: the result is the two measurements combined, each by its
  /// information. Few matches on one plain wall leave the yaw to a fraction of a degree; the
  /// pixels with a gradient and the depth pin the step from the previous frame down.
  bool few_inliers_dense = true;
  /// Pixels sampled per pyramid level (evenly) by that alignment; by default as many as the
  /// fallback samples. Fewer cost less time, but the result counts only where the pixels outweigh
  /// the features' prior in at least three directions (DenseAlignmentOptions::
  /// min_constrained_directions), and with fewer pixels that holds on fewer frames.
  int few_inliers_dense_max_pixels = 20000;

  // --- FOVIS front end ------------------------------------------------------------------------
  int fovis_levels = 3;
  int fovis_fast_threshold = 20;
  int fovis_max_sad = 1800;
  double fovis_clique_tolerance_m = 0.02;

  // --- Keyframes and failures -----------------------------------------------------------------
  // A new keyframe comes from novelty: when fewer than keyframe_min_overlap of the keyframe's
  // features (with depth) are still tracked, or fewer than keyframe_min_inliers. The baseline
  // bounds (distance, as a fraction of the keyframe's median depth and absolute, and rotation)
  // keep the keyframe's appearance a good predictor of the current view, without making a
  // keyframe every few frames of a walk or a turn that still sees the same things.
  int keyframe_min_inliers = 50;
  double keyframe_min_overlap = 0.4;
  double keyframe_max_baseline_ratio = 0.12;  ///< distance / keyframe's median feature depth
  double keyframe_max_translation_m = 0.5;
  double keyframe_max_rotation_deg = 30.0;
  int keyframe_window = 30;
  /// Before making a keyframe, also try the map's keyframes near the pose
  /// (VisualOdometry::setMapKeyframes).
  bool map_keyframes = true;
  int max_predicted_frames = 5;
  // After LOST, the first trackable frame is matched against the most recent keyframes (guided at
  // the last pose, then over the whole image) before a new segment starts at it: a camera that
  // comes back to what it saw before the loss continues in the same world frame at once.
  int relocalization_keyframes = 3;
  int relocalization_min_inliers = 50;
  // While the back end has not yet placed the current segment in its map (after a loss, or at the
  // start of a run in a loaded session), every keyframe it gets is a relocalisation attempt. A
  // frame whose view has changed by relocalization_keyframe_novelty of what makes a keyframe then
  // becomes one, so that the attempts follow the view rather than the slower keyframe rate; the
  // first may come relocalization_keyframe_interval_s after the last keyframe, and each further
  // one of the segment waits twice as long as the one before, up to
  // relocalization_keyframe_max_interval_s, so that a segment that never joins the map (a new
  // place, a wrong map) adds few keyframes for it.
  double relocalization_keyframe_interval_s = 0.25;
  double relocalization_keyframe_max_interval_s = 2.0;
  double relocalization_keyframe_novelty = 0.5;
  double failure_sigma_scale = 10.0;

  // --- Dense alignment where features fail (dense_alignment.hpp) ------------------------------
  bool dense_fallback = true;
  int dense_levels = 4;
  int dense_finest_level = 1;
  double dense_min_gradient = 4.0;
  double dense_min_gradient_share = 0.0;
  double dense_min_coarse_gradient_share = 0.1;

  // --- The motion prior: constant velocity, and how far a frame may depart from it -----------
  /// 1-sigma change of speed (m/s) and turn rate (deg/s) between frames: the prior's sigmas are
  /// these times the interval. Dense alignment's prior, and the disagreement gate's.
  double motion_prior_sigma_mps = 0.6;
  double motion_prior_sigma_degps = 60.0;
  /// A feature estimate further than this (Mahalanobis distance, in sigmas, prior and estimate
  /// covariance combined) from the constant-velocity prediction is rejected and retried; 0 = off.
  double motion_prior_gate_sigma = 6.0;

  // --- Plausibility ---------------------------------------------------------------------------
  /// An estimate implying faster motion is vetoed and tracking retried. Not tracking.* keys:
  /// load() reads the filter's filter.max_speed_mps and filter.max_angular_rate_radps.
  MotionLimits motion_limits;

  /// The `tracking.*` keys.
  static const ConfigSchema<TrackingConfig>& schema();
  /// Reads `tracking.*` from config (missing keys take the defaults above). Throws ConfigError.
  static TrackingConfig load(Config& config);
};

}  // namespace slamd
