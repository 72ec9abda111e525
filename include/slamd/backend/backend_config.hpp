#pragma once
// BackendConfig: every option of the back end (pose graph, optimiser, place recognition), read
// from the `backend.*` keys.
//
//   Config config = Config::fromFile("config/synthetic.yaml");
//   BackendConfig backend = BackendConfig::load(config);   // throws ConfigError when invalid

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

/// Robust kernel applied to the whitened error of an edge (key backend.robust_kernel).
enum class RobustKernel { kNone, kHuber, kCauchy };

const char* robustKernelName(RobustKernel kernel);

/// What the back end does with a loaded session (--session-in; key backend.mode).
enum class BackendMode {
  kSlam,      ///< new keyframes join the loaded map, which the new run extends
  kLocalize,  ///< the loaded map is a fixed reference: the run only localises in it
};

const char* backendModeName(BackendMode mode);

// Each key's type, default, range, unit and doc: backend_config.cpp (its one declaration), or
// `slamd --describe-config backend`.
struct BackendConfig {
  bool enabled = false;
  BackendMode mode = BackendMode::kSlam;

  // --- Pose-graph optimisation ----------------------------------------------------------------
  RobustKernel robust_kernel = RobustKernel::kCauchy;
  double robust_kernel_width = 2.0;  ///< whitened error (standard deviations)
  bool robust_odometry_edges = false;
  int max_iterations = 30;
  double initial_lambda = 1e-4;
  double relative_cost_tolerance = 1e-6;
  double step_tolerance = 1e-6;
  double odometry_sigma_ratio = 0.02;
  double odometry_sigma_rad = 0.005;

  // --- Place recognition ----------------------------------------------------------------------
  int vocabulary_branching = 8;
  int vocabulary_depth = 3;
  double loop_min_score = 0.05;
  double loop_min_score_ratio = 0.5;
  int loop_exclude_recent = 20;
  int loop_max_candidates = 5;
  int loop_min_inliers = 40;
  double loop_inlier_threshold_px = 3.0;
  int loop_ransac_iterations = 200;
  double loop_match_ratio = 0.8;
  int loop_max_descriptor_distance = 64;
  bool align_patches = true;
  int loop_consistency = 2;
  int loop_consistency_window = 5;

  /// Reject a verified loop whose relative pose disagrees with odometry (same tracking segment)
  /// by more than loop_max_drift_m + loop_max_drift_ratio * path length. Repeated textures and
  /// uniform corridors make distant places look and fit alike (perceptual aliasing); odometry
  /// drift is far smaller than such jumps.
  bool loop_check_odometry = true;
  double loop_max_drift_m = 1.0;
  double loop_max_drift_ratio = 0.1;

  // --- Local (covisibility) edges -------------------------------------------------------------
  /// Geometric edges from each new keyframe to earlier keyframes of the same connected map that
  /// see the same place (BoW retrieval over all stored keyframes, then RANSAC + refinement), on
  /// top of the odometry edge. They make the graph rigid in scenes that are revisited constantly
  /// (a desk), where rare loops alone leave the drift.
  int local_edges = 6;
  int local_max_candidates = 12;
  int local_min_inliers = 30;
  double local_search_radius_px = 40.0;
  double local_max_discrepancy_m = 0.15;
  double local_max_discrepancy_ratio = 0.05;
  double local_max_discrepancy_rad = 0.2;
  double local_min_sigma_m = 0.002;
  double local_min_sigma_rad = 0.002;
  /// The local edges a keyframe adds are all measured from its features: each gets 1/n of its
  /// information when there are n (covariance intersection), so that together they count those
  /// observations once.
  bool local_edges_share_information = true;
  bool optimize_every_keyframe = true;
  /// An optimisation brought by local edges (or by a loop already nearly closed) moves only the
  /// keyframes within local_window_hops edges of the new one (at most local_window_size); the
  /// rest is held. A scene revisited constantly connects every keyframe to every other, and the
  /// factorisation of the whole graph grows nearly cubically with its size.
  int local_window_hops = 2;
  int local_window_size = 40;
  double full_optimization_chi2 = 50.0;
  /// The daemon runs whole-graph optimisations on a thread of their own (BackgroundOptimizer)
  /// and merges them when done; per keyframe the back end then costs a local window only.
  bool full_optimization_in_background = true;
  int local_max_iterations = 10;

  // --- Keyframe culling ------------------------------------------------------------------------
  /// A new keyframe is redundant, and culled, when the earlier keyframes that verifiably see its
  /// place hold what it holds: ORB-SLAM's rule (90% of a keyframe's points seen by at least 3
  /// other keyframes), with views for landmarks. A feature with depth counts as seen by a
  /// keyframe whose verified local match (at least cull_min_inliers inliers) puts it inside that
  /// keyframe's image, in front, at most 1.2x (one ORB level) farther away. A keyframe whose
  /// features with depth are nearly all (cull_min_covered_ratio) inliers of one verified match
  /// is the same view again and redundant too. Revisiting a place then adds no keyframes; only
  /// new ground does.
  bool cull_redundant_keyframes = true;
  /// A kept new keyframe also culls the earlier keyframes it matched that are now covered by the
  /// same rule (their views: every keyframe in the graph that ever verifiably matched them).
  bool cull_earlier_keyframes = true;
  int cull_min_inliers = 100;
  int cull_min_covering_keyframes = 3;
  double cull_min_covered_ratio = 0.9;

  // --- Relocalisation -------------------------------------------------------------------------
  bool relocalization = true;
  int relocalization_min_inliers = 40;

  // --- Vocabulary -----------------------------------------------------------------------------
  std::string vocabulary_file;

  /// The `backend.*` keys.
  static const ConfigSchema<BackendConfig>& schema();
  /// Reads and validates backend.*; throws ConfigError.
  static BackendConfig load(Config& config);
};

}  // namespace slamd
