#pragma once
// BackendConfig: every option of the back end (pose graph, optimiser, place recognition), read
// from the `backend.*` keys.
//
//   Config config = Config::fromFile("config/synthetic.yaml");
//   BackendConfig backend = BackendConfig::load(config);   // throws ConfigError when invalid
//
// Each member documents its key, type, default, allowed range and unit.

#include <string>

#include "slamd/common/config.hpp"

namespace slamd {

/// Robust kernel applied to the whitened error of an edge (key backend.robust_kernel).
enum class RobustKernel { kNone, kHuber, kCauchy };

const char* robustKernelName(RobustKernel kernel);

struct BackendConfig {
  /// backend.enabled (bool, default false): run the back end (loop closing, pose graph).
  bool enabled = false;

  // --- Pose-graph optimisation ----------------------------------------------------------------
  /// backend.robust_kernel (choice none|huber|cauchy, default cauchy): kernel on robust edges
  /// (loop edges; odometry edges too when robust_odometry_edges). Cauchy rejects wrong loops
  /// almost completely (it is warm-started with Huber); Huber only bounds their pull.
  RobustKernel robust_kernel = RobustKernel::kCauchy;
  /// backend.robust_kernel_width (double, default 2.0, range [0.01, 100], unit: whitened
  /// error, i.e. standard deviations): where the kernel leaves the quadratic.
  double robust_kernel_width = 2.0;
  /// backend.robust_odometry_edges (bool, default false): apply the kernel to odometry edges.
  bool robust_odometry_edges = false;
  /// backend.max_iterations (int, default 30, range [1, 1000]): Levenberg-Marquardt iterations.
  int max_iterations = 30;
  /// backend.initial_lambda (double, default 1e-4, range [1e-12, 1e6], unitless): initial LM
  /// damping, relative to the diagonal of the normal equations.
  double initial_lambda = 1e-4;
  /// backend.relative_cost_tolerance (double, default 1e-6, range [0, 1]): stop when an accepted
  /// step lowers the cost by less than this fraction.
  double relative_cost_tolerance = 1e-6;
  /// backend.step_tolerance (double, default 1e-6, range [0, 1], unit: tangent norm, metres /
  /// radians): stop when the update is this small.
  double step_tolerance = 1e-6;

  /// backend.odometry_sigma_ratio (double, default 0.02, range [1e-4, 1], metres per metre):
  /// standard deviation of an odometry edge's translation per metre between the keyframes
  /// (plus 5 mm), per axis.
  double odometry_sigma_ratio = 0.02;
  /// backend.odometry_sigma_rad (double, default 0.005, range [1e-5, 1], radians): standard
  /// deviation of an odometry edge's rotation, per axis.
  double odometry_sigma_rad = 0.005;

  // --- Place recognition ----------------------------------------------------------------------
  /// backend.vocabulary_branching (int, default 8, range [2, 32]): children per vocabulary node.
  int vocabulary_branching = 8;
  /// backend.vocabulary_depth (int, default 3, range [1, 6]): levels of the vocabulary tree
  /// (words = branching^depth at most).
  int vocabulary_depth = 3;
  /// backend.loop_min_score (double, default 0.05, range [0, 1], unitless): minimum TF-IDF
  /// cosine similarity (L1-normalised BoW vectors, score in [0, 1]) of a loop candidate.
  double loop_min_score = 0.05;
  /// backend.loop_min_score_ratio (double, default 0.5, range [0, 10], unitless): minimum score
  /// relative to the score against the previous keyframe (0 disables).
  double loop_min_score_ratio = 0.5;
  /// backend.loop_exclude_recent (int, default 20, range [0, 100000], keyframes): the latest
  /// keyframes never considered as loop candidates.
  int loop_exclude_recent = 20;
  /// backend.loop_max_candidates (int, default 5, range [1, 100]): candidates verified per
  /// keyframe.
  int loop_max_candidates = 5;
  /// backend.loop_min_inliers (int, default 40, range [6, 10000]): RANSAC + refinement inliers
  /// for a geometrically verified loop.
  int loop_min_inliers = 40;
  /// backend.loop_inlier_threshold_px (double, default 3.0, range [0.5, 50], pixels): RANSAC
  /// reprojection threshold.
  double loop_inlier_threshold_px = 3.0;
  /// backend.loop_ransac_iterations (int, default 200, range [10, 100000]).
  int loop_ransac_iterations = 200;
  /// backend.loop_match_ratio (double, default 0.8, range [0.3, 1.0]): descriptor ratio test.
  double loop_match_ratio = 0.8;
  /// backend.loop_max_descriptor_distance (int, default 64, range [1, 256], bits): Hamming
  /// distance above which a match is discarded.
  int loop_max_descriptor_distance = 64;
  /// backend.align_patches (bool, default true): before the refinement of a verified match,
  /// align each inlier's reference patch in the query image (sub-pixel, as tracking does) with
  /// the front end's default undistortion; off uses the ORB keypoint positions.
  bool align_patches = true;
  /// backend.loop_consistency (int, default 2, range [1, 20], keyframes): consecutive
  /// keyframes whose verified candidates must agree (neighbouring ids) before a loop is accepted.
  int loop_consistency = 2;
  /// backend.loop_consistency_window (int, default 5, range [0, 1000], keyframe ids): how far
  /// apart two candidate ids may be and still count as the same place.
  int loop_consistency_window = 5;

  /// backend.loop_check_odometry (bool, default true): reject a verified loop whose relative
  /// pose disagrees with the odometry poses of the two keyframes (same tracking segment only) by
  /// more than loop_max_drift_m + loop_max_drift_ratio * path length between them. Repeated
  /// textures and uniform corridors make distant places look and fit alike (perceptual
  /// aliasing); odometry drift is far smaller than such jumps.
  bool loop_check_odometry = true;
  /// backend.loop_max_drift_m (double, default 1.0, range [0, 1000], metres).
  double loop_max_drift_m = 1.0;
  /// backend.loop_max_drift_ratio (double, default 0.1, range [0, 10], metres per metre
  /// travelled).
  double loop_max_drift_ratio = 0.1;

  // --- Local (covisibility) edges -------------------------------------------------------------
  /// backend.local_edges (int, default 6, range [0, 50]): geometric edges added from each new
  /// keyframe to earlier keyframes of the same connected map that see the same place (BoW
  /// retrieval over all stored keyframes, recent ones included, then RANSAC + refinement), on
  /// top of the odometry edge. 0 disables them (loops only). They make the graph rigid in scenes
  /// that are revisited constantly (a desk), where rare loops alone leave the drift.
  int local_edges = 6;
  /// backend.local_max_candidates (int, default 12, range [1, 200]): candidates verified per
  /// keyframe for local edges (best BoW scores first).
  int local_max_candidates = 12;
  /// backend.local_min_inliers (int, default 30, range [6, 10000]): inliers after refinement for
  /// a local edge.
  int local_min_inliers = 30;
  /// backend.local_search_radius_px (double, default 40, range [2, 1000], pixels): local edges
  /// match descriptors only this far from where the graph's estimate projects each point.
  double local_search_radius_px = 40.0;
  /// backend.local_max_discrepancy_m (double, default 0.15, range [0, 100], metres) and
  /// backend.local_max_discrepancy_ratio (double, default 0.05, range [0, 10], metres per metre
  /// travelled): a local edge is rejected when its translation disagrees with the current graph
  /// estimate of the relative pose by more than this (plus the ratio times the path between the
  /// two keyframes): the false-match protection of edges that need no consistency check.
  double local_max_discrepancy_m = 0.15;
  double local_max_discrepancy_ratio = 0.05;
  /// backend.local_max_discrepancy_rad (double, default 0.2, range [0, 3.2], radians): the same
  /// for the rotation.
  double local_max_discrepancy_rad = 0.2;
  /// backend.local_min_sigma_m (double, default 0.002, range [0, 1], metres) and
  /// backend.local_min_sigma_rad (double, default 0.002, range [0, 1], radians): floor added (in
  /// quadrature) to the refinement's standard deviations of a local edge.
  double local_min_sigma_m = 0.002;
  double local_min_sigma_rad = 0.002;
  /// backend.optimize_every_keyframe (bool, default true): re-optimise after every keyframe that
  /// brought a local edge (otherwise only after loops and relocalisations).
  bool optimize_every_keyframe = true;
  /// backend.local_window_hops (int, default 2, range [0, 100]) and backend.local_window_size
  /// (int, default 40, range [2, 100000], keyframes): an optimisation brought by local edges (or
  /// by a loop that is already nearly closed) moves only the new keyframe and the keyframes
  /// within this many edges of it (at most local_window_size, nearest first); the rest of the
  /// graph is held. A scene revisited constantly connects every keyframe to every other, and
  /// the factorisation of the whole graph grows nearly cubically with its size. 0 hops = always
  /// optimise the whole graph.
  int local_window_hops = 2;
  int local_window_size = 40;
  /// backend.full_optimization_chi2 (double, default 50, range [0, 1e12], whitened squared
  /// error): a loop edge, or a local edge to a keyframe beyond the local window, whose error at
  /// the current estimate exceeds this re-optimises the whole graph; below, the local window
  /// suffices. Relocalisations always re-optimise the whole graph.
  double full_optimization_chi2 = 50.0;
  /// backend.local_max_iterations (int, default 10, range [1, 1000]): Levenberg-Marquardt
  /// iterations of an optimisation brought only by local edges (warm-started from the previous
  /// solution, it has little left to do); loops and relocalisations use max_iterations.
  int local_max_iterations = 10;

  // --- Relocalisation -------------------------------------------------------------------------
  /// backend.relocalization (bool, default true): a keyframe that starts a new tracking segment
  /// (after LOST) is matched against every keyframe of earlier segments (no recency exclusion,
  /// no consistency); a verified match ties the segment back into the map with a strong edge.
  /// Until one matches, each later keyframe of the segment tries again.
  bool relocalization = true;
  /// backend.relocalization_min_inliers (int, default 40, range [6, 10000]): inliers after
  /// refinement for a relocalisation.
  int relocalization_min_inliers = 40;

  // --- Vocabulary -----------------------------------------------------------------------------
  /// backend.vocabulary_file (string, default empty): vocabulary written by slamd-vocabulary;
  /// empty = train one at start-up on slamd's synthetic room (about a second).
  std::string vocabulary_file;

  /// Reads and validates backend.*; throws ConfigError.
  static BackendConfig load(Config& config);
};

}  // namespace slamd
