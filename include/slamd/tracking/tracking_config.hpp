#pragma once
// TrackingConfig: every option of visual odometry, read from the `tracking.*` keys.
//
//   Config config = Config::fromFile("config/tum_fr1.yaml");
//   TrackingConfig tracking = TrackingConfig::load(config);   // throws ConfigError when invalid
//
// Each member documents its key, type, default, allowed range and unit.

#include <string>

#include "slamd/common/config.hpp"

namespace slamd {

/// Feature front end used by VisualOdometry (key tracking.frontend).
enum class FrontEndType { kOrb, kSift, kFovis };

const char* frontEndName(FrontEndType type);

struct TrackingConfig {
  /// tracking.frontend (choice orb|sift|fovis, default orb).
  FrontEndType frontend = FrontEndType::kOrb;

  // --- Features -------------------------------------------------------------------------------
  /// tracking.max_features (int, default 1000, range [50, 10000]): features kept per frame.
  int max_features = 1000;
  /// tracking.grid_cols / tracking.grid_rows (int, default 8 x 6, range [1, 64]): spatial
  /// buckets; each bucket keeps at most max_features / (cols * rows) of its strongest features.
  int grid_cols = 8;
  int grid_rows = 6;
  /// tracking.orb_levels (int, default 3, range [1, 12]): ORB pyramid levels (scale 1.2). Few
  /// levels: fr1/xyz-like motion needs little scale range, and it halves extraction time.
  int orb_levels = 3;
  /// tracking.orb_fast_threshold (int, default 20, range [1, 100]): ORB FAST threshold, grey
  /// levels (stronger corners localise better).
  int orb_fast_threshold = 20;
  /// tracking.subpixel (bool, default true): refine level-0 ORB/FAST corners to sub-pixel.
  bool subpixel = true;
  /// tracking.patch_refinement (bool, default true): refine each inlier's position in the current
  /// image by aligning the reference image's 9x9 patch around its keypoint (Lucas-Kanade,
  /// translation + brightness offset), as FOVIS refines its matches; then re-estimate.
  bool patch_refinement = true;
  /// tracking.align_blur_sigma_px (double, default 1.0, range [0, 5], pixels): Gaussian blur of
  /// the images used for patch refinement (0 = none): it damps aliasing and sensor noise, which
  /// otherwise shift the aligned positions by tenths of a pixel.
  double align_blur_sigma_px = 1.0;
  /// tracking.undistort (bool, default true): undistort keypoints with the plumb-bob
  /// coefficients of the frame's intrinsics before any geometry.
  bool undistort = true;
  /// tracking.min_depth_m / tracking.max_depth_m (double, default 0.3 / 5.0, range [0.05, 100],
  /// metres): depth measurements outside this range are ignored.
  double min_depth_m = 0.3;
  double max_depth_m = 5.0;

  // --- Matching -------------------------------------------------------------------------------
  /// tracking.match_ratio (double, default 0.8, range [0.3, 1.0]): Lowe ratio, best / second.
  double match_ratio = 0.8;
  /// tracking.max_descriptor_distance (int, default 64, range [1, 256]): largest Hamming distance
  /// accepted for ORB (SIFT uses 0.0 < L2 < 350, FOVIS its own SAD bound).
  int max_descriptor_distance = 64;
  /// tracking.search_radius_px (double, default 20, range [2, 200], pixels): radius of the
  /// projection-guided search around a keypoint's predicted position.
  double search_radius_px = 20.0;
  /// tracking.refine_search_radius_px (double, default 4, range [0, 50], pixels): radius of the
  /// second guided search with the estimated pose (0 = off).
  double refine_search_radius_px = 4.0;
  /// tracking.min_guided_matches (int, default 60, range [3, 10000]): fewer guided matches than
  /// this fall back to matching by descriptor over the whole image.
  int min_guided_matches = 60;

  /// tracking.outlier_rejection (choice auto|ransac|clique, default auto): how inliers are found
  /// before refinement; auto = clique for fovis (as FOVIS), RANSAC for orb and sift.
  enum class OutlierRejection { kAuto, kRansac, kClique };
  OutlierRejection outlier_rejection = OutlierRejection::kAuto;
  bool useClique() const {
    return outlier_rejection == OutlierRejection::kClique ||
           (outlier_rejection == OutlierRejection::kAuto && frontend == FrontEndType::kFovis);
  }

  /// tracking.rotation_prior (choice auto|on|off, default auto): predict the rotation from image
  /// alignment of 80x60 blurred images (FOVIS) instead of constant velocity; auto = fovis only.
  enum class Switch { kAuto, kOn, kOff };
  Switch rotation_prior = Switch::kAuto;
  bool useRotationPrior() const {
    return rotation_prior == Switch::kOn ||
           (rotation_prior == Switch::kAuto && frontend == FrontEndType::kFovis);
  }

  // --- Motion estimation ----------------------------------------------------------------------
  /// tracking.ransac_iterations (int, default 200, range [1, 100000]): upper bound on RANSAC
  /// hypotheses (fewer are drawn when the inlier ratio is high, at 99.9% confidence).
  int ransac_iterations = 200;
  /// tracking.inlier_threshold_px (double, default 3.0, range [0.1, 50], pixels): reprojection
  /// error bound for inliers.
  double inlier_threshold_px = 3.0;
  /// tracking.min_inliers (int, default 15, range [3, 10000]): fewer inliers fail the frame.
  int min_inliers = 15;
  /// tracking.min_features (int, default 20, range [3, 10000]): fewer features with depth fail
  /// the frame with INSUFFICIENT_FEATURES.
  int min_features = 20;
  /// tracking.max_iterations (int, default 10, range [1, 100]): Gauss-Newton/LM iterations.
  int max_iterations = 10;
  /// tracking.pixel_sigma_px (double, default 1.0, range [0.05, 20], pixels): keypoint noise at
  /// pyramid level 0 (scaled by the level's scale factor).
  double pixel_sigma_px = 1.0;
  /// tracking.depth_sigma_coeff (double, default 0.0015, range [0, 1], 1/metres): depth noise
  /// sigma_z = depth_sigma_coeff * z^2 (Kinect-type sensors); 0 disables the depth residual.
  double depth_sigma_coeff = 0.0015;
  /// tracking.estimate_noise_scale (bool, default true): refinement estimates the actual noise of
  /// the reprojection and depth residuals (median residual) and weighs each kind by it, instead
  /// of trusting pixel_sigma_px and depth_sigma_coeff as they are.
  bool estimate_noise_scale = true;
  /// tracking.huber_k (double, default 1.5, range [0.1, 100], sigmas): Huber kernel width (in
  /// estimated sigmas with estimate_noise_scale; near the textbook 1.345).
  double huber_k = 1.5;

  /// tracking.joint_references (int, default -1, range [-1, 10]): after tracking the keyframe,
  /// the pose is refined jointly against this many more recent keyframes, their odometry poses
  /// held fixed (a local window that damps the drift of chained keyframe measurements); 0 = the
  /// keyframe alone; -1 = auto: 2 for orb and sift, 0 for fovis (whose budget is 8 ms a frame).
  int joint_references = -1;
  int jointReferences() const {
    if (joint_references >= 0) return joint_references;
    return frontend == FrontEndType::kFovis ? 0 : 2;
  }
  /// tracking.joint_max_matches (int, default 150, range [10, 10000]): matches used per extra
  /// reference in the joint refinement (a sample spread over the image).
  int joint_max_matches = 150;

  // --- FOVIS front end ------------------------------------------------------------------------
  /// tracking.fovis_levels (int, default 3, range [1, 5]): pyramid levels.
  int fovis_levels = 3;
  /// tracking.fovis_fast_threshold (int, default 20, range [5, 100], grey levels): initial FAST
  /// threshold; adapted each frame towards max_features.
  int fovis_fast_threshold = 20;
  /// tracking.fovis_max_sad (int, default 1800, range [1, 20000]): largest sum of absolute
  /// differences of two 9x9 brightness-normalised patches accepted as a match.
  int fovis_max_sad = 1800;
  /// tracking.fovis_clique_tolerance_m (double, default 0.02, range [0.001, 1], metres): two
  /// matches are consistent when their 3D distances differ by less than this plus the depth
  /// noise of both points.
  double fovis_clique_tolerance_m = 0.02;

  // --- Keyframes and failures -----------------------------------------------------------------
  /// tracking.keyframe_min_inliers (int, default 100, range [3, 10000]): fewer inliers against
  /// the keyframe make the current frame a keyframe.
  int keyframe_min_inliers = 100;
  /// tracking.keyframe_min_overlap (double, default 0.4, range [0, 1]): fraction of the
  /// keyframe's features with depth still tracked; below it the current frame becomes a keyframe.
  double keyframe_min_overlap = 0.4;
  /// tracking.keyframe_max_translation_m (double, default 0.15, range [0.001, 100], metres).
  double keyframe_max_translation_m = 0.15;
  /// tracking.keyframe_max_rotation_deg (double, default 10, range [0.1, 180], degrees).
  double keyframe_max_rotation_deg = 10.0;
  /// tracking.keyframe_window (int, default 30, range [1, 1000]): recent keyframes kept; when a
  /// new keyframe is due, a recent one near the current pose is re-used if it tracks well
  /// (1 = never re-use). Each keeps its frame (about 3 MB at 640x480). On fr1/xyz, which
  /// revisits the same places, 30 instead of 10 halves the ORB ATE (0.024 -> 0.012 m).
  int keyframe_window = 30;
  /// tracking.max_predicted_frames (int, default 5, range [0, 1000]): consecutive failed frames
  /// bridged by constant-velocity prediction before tracking is declared LOST.
  int max_predicted_frames = 5;
  /// tracking.failure_sigma_scale (double, default 10, range [1, 1e6]): covariance inflation of
  /// a predicted (failed) frame relative to the last good frame's.
  double failure_sigma_scale = 10.0;

  /// Reads `tracking.*` from config (missing keys take the defaults above). Throws ConfigError.
  static TrackingConfig load(Config& config);
};

}  // namespace slamd
