#include "slamd/backend/backend_config.hpp"

namespace slamd {

namespace {

const EnumNames<RobustKernel> kRobustKernelNames = {
    {RobustKernel::kNone, "none", "plain least squares"},
    {RobustKernel::kHuber, "huber", "bounds the pull of a wrong edge"},
    {RobustKernel::kCauchy, "cauchy",
     "rejects wrong loops almost completely (warm-started with Huber)"},
};

const EnumNames<BackendMode> kBackendModeNames = {
    {BackendMode::kSlam, "slam",
     "new keyframes join a loaded session's map and extend it; loops to it close"},
    {BackendMode::kLocalize, "localize",
     "a loaded session's map is a fixed reference: poses are localised in it, the map is not "
     "changed"},
};

}  // namespace

const char* backendModeName(BackendMode mode) { return enumText(kBackendModeNames, mode); }

const char* robustKernelName(RobustKernel kernel) { return enumText(kRobustKernelNames, kernel); }

const ConfigSchema<BackendConfig>& BackendConfig::schema() {
  using C = BackendConfig;
  static const auto table =
      ConfigSchema<C>("backend")
          .flag("enabled", &C::enabled, "run the back end (loop closing, pose graph)")
          .choice("mode", &C::mode, kBackendModeNames,
                  "with a session loaded (--session-in): extend its map, or only localise in it")
          .choice("robust_kernel", &C::robust_kernel, kRobustKernelNames,
                  "kernel on robust edges (loop edges; odometry edges too with "
                  "robust_odometry_edges)")
          .number("robust_kernel_width", &C::robust_kernel_width, 0.01, 100.0, "sigmas",
                  "whitened error where the kernel leaves the quadratic")
          .flag("robust_odometry_edges", &C::robust_odometry_edges,
                "apply the kernel to odometry edges")
          .number("max_iterations", &C::max_iterations, 1, 1000, "",
                  "Levenberg-Marquardt iterations")
          .number("initial_lambda", &C::initial_lambda, 1e-12, 1e6, "",
                  "initial LM damping, relative to the diagonal of the normal equations")
          .number("relative_cost_tolerance", &C::relative_cost_tolerance, 0.0, 1.0, "",
                  "stop when an accepted step lowers the cost by less than this fraction")
          .number("step_tolerance", &C::step_tolerance, 0.0, 1.0, "m, rad",
                  "stop when the update's tangent norm is this small")
          .number("odometry_sigma_ratio", &C::odometry_sigma_ratio, 1e-4, 1.0, "m/m",
                  "odometry edge translation sigma per metre between the keyframes (plus 5 mm), "
                  "per axis")
          .number("odometry_sigma_rad", &C::odometry_sigma_rad, 1e-5, 1.0, "rad",
                  "odometry edge rotation sigma, per axis")
          .number("vocabulary_branching", &C::vocabulary_branching, 2, 32, "",
                  "children per vocabulary node (slamd-vocabulary training)")
          .number("vocabulary_depth", &C::vocabulary_depth, 1, 6, "",
                  "levels of the vocabulary tree (words = branching^depth at most; "
                  "slamd-vocabulary training)")
          .number("loop_min_score", &C::loop_min_score, 0.0, 1.0, "",
                  "minimum TF-IDF cosine similarity (L1-normalised BoW vectors) of a loop "
                  "candidate")
          .number("loop_min_score_ratio", &C::loop_min_score_ratio, 0.0, 10.0, "",
                  "minimum score relative to the score against the previous keyframe (0 "
                  "disables)")
          .number("loop_exclude_recent", &C::loop_exclude_recent, 0, 100000, "keyframes",
                  "the latest keyframes never considered as loop candidates")
          .number("loop_max_candidates", &C::loop_max_candidates, 1, 100, "",
                  "candidates verified per keyframe")
          .number("loop_min_inliers", &C::loop_min_inliers, 6, 10000, "",
                  "RANSAC + refinement inliers for a geometrically verified loop")
          .number("loop_inlier_threshold_px", &C::loop_inlier_threshold_px, 0.5, 50.0, "px",
                  "RANSAC reprojection threshold")
          .number("loop_ransac_iterations", &C::loop_ransac_iterations, 10, 100000, "",
                  "RANSAC hypotheses of a loop verification")
          .number("loop_match_ratio", &C::loop_match_ratio, 0.3, 1.0, "", "descriptor ratio test")
          .number("loop_max_descriptor_distance", &C::loop_max_descriptor_distance, 1, 256, "bits",
                  "Hamming distance above which a match is discarded")
          .flag("align_patches", &C::align_patches,
                "before refining a verified match, align each inlier's reference patch in the "
                "query image (sub-pixel, as tracking does); off uses the ORB keypoint positions")
          .number("loop_consistency", &C::loop_consistency, 1, 20, "keyframes",
                  "consecutive keyframes whose verified candidates must agree before a loop is "
                  "accepted")
          .number("loop_consistency_window", &C::loop_consistency_window, 0, 1000, "keyframe ids",
                  "how far apart two candidate ids may be and still agree")
          .flag("loop_check_odometry", &C::loop_check_odometry,
                "reject a verified loop that disagrees with odometry by more than "
                "loop_max_drift_m + loop_max_drift_ratio * path length (perceptual aliasing)")
          .number("loop_max_drift_m", &C::loop_max_drift_m, 0.0, 1000.0, "m",
                  "constant part of the allowed disagreement")
          .number("loop_max_drift_ratio", &C::loop_max_drift_ratio, 0.0, 10.0, "m/m",
                  "allowed disagreement per metre travelled")
          .number("local_edges", &C::local_edges, 0, 50, "",
                  "geometric edges from each new keyframe to earlier keyframes that see the same "
                  "place; 0 = loops only")
          .number("local_max_candidates", &C::local_max_candidates, 1, 200, "",
                  "candidates verified per keyframe for local edges and culling (best BoW scores "
                  "first; without culling the search stops at local_edges verified ones)")
          .number("local_min_inliers", &C::local_min_inliers, 6, 10000, "",
                  "inliers after refinement for a local edge")
          .number("local_search_radius_px", &C::local_search_radius_px, 2.0, 1000.0, "px",
                  "local edges match only this far from where the graph's estimate projects "
                  "each point")
          .number("local_max_discrepancy_m", &C::local_max_discrepancy_m, 0.0, 100.0, "m",
                  "reject a local edge whose translation disagrees with the graph's estimate by "
                  "more than this (plus the ratio times the path between the keyframes)")
          .number("local_max_discrepancy_ratio", &C::local_max_discrepancy_ratio, 0.0, 10.0, "m/m",
                  "allowed translation disagreement per metre travelled")
          .number("local_max_discrepancy_rad", &C::local_max_discrepancy_rad, 0.0, 3.2, "rad",
                  "the same for the rotation")
          .number("local_min_sigma_m", &C::local_min_sigma_m, 0.0, 1.0, "m",
                  "floor added in quadrature to a local edge's translation sigma")
          .number("local_min_sigma_rad", &C::local_min_sigma_rad, 0.0, 1.0, "rad",
                  "floor added in quadrature to a local edge's rotation sigma")
          .flag("local_edges_share_information", &C::local_edges_share_information,
                "the n local edges of a keyframe, measured from the same features, each get 1/n "
                "of their information (covariance intersection), so that those observations "
                "count once")
          .flag("optimize_every_keyframe", &C::optimize_every_keyframe,
                "re-optimise after every keyframe that brought a local edge (otherwise only "
                "after loops and relocalisations)")
          .number("local_max_iterations", &C::local_max_iterations, 1, 1000, "",
                  "LM iterations of an optimisation brought only by local edges (warm-started)")
          .number("local_window_hops", &C::local_window_hops, 0, 100, "edges",
                  "a local optimisation moves only keyframes within this many edges of the new "
                  "one; 0 = always optimise the whole graph")
          .number("local_window_size", &C::local_window_size, 2, 100000, "keyframes",
                  "at most this many keyframes in the local window, nearest first")
          .number("full_optimization_chi2", &C::full_optimization_chi2, 0.0, 1e12, "",
                  "a loop edge, or a local edge beyond the window, whose whitened squared error "
                  "exceeds this re-optimises the whole graph")
          .flag("full_optimization_in_background", &C::full_optimization_in_background,
                "in the daemon, whole-graph optimisations run on a thread of their own and are "
                "merged when done (the keyframe that asked gets its local window meanwhile); "
                "false = in the back-end thread, before the next keyframe")
          .flag("cull_redundant_keyframes", &C::cull_redundant_keyframes,
                "remove a new keyframe whose features other keyframes already see (ORB-SLAM's "
                "rule, see cull_*), or whose features are nearly all (cull_min_covered_ratio) "
                "inliers of one verified match; its odometry and loop edges are merged into the "
                "keyframe that sees it best, its frames stay anchored through that keyframe")
          .flag("cull_earlier_keyframes", &C::cull_earlier_keyframes,
                "with cull_redundant_keyframes: a kept new keyframe also culls the earlier "
                "keyframes it verifiably matched whose features the keyframes that see them now "
                "cover by the same rule; they are merged into the new keyframe")
          .number("cull_min_inliers", &C::cull_min_inliers, 6, 100000, "",
                  "inliers of a verified local match for that keyframe to count as seeing the "
                  "new keyframe's place")
          .number("cull_min_covering_keyframes", &C::cull_min_covering_keyframes, 1, 50,
                  "keyframes", "a feature is covered when this many such keyframes see it")
          .number("cull_min_covered_ratio", &C::cull_min_covered_ratio, 0.0, 1.0, "",
                  "a keyframe is redundant when this fraction of its features with depth is "
                  "covered")
          .flag("relocalization", &C::relocalization,
                "match a keyframe that starts a new tracking segment (after LOST) against every "
                "earlier segment's keyframes; a match ties the segment back into the map")
          .number("relocalization_min_inliers", &C::relocalization_min_inliers, 6, 10000, "",
                  "inliers after refinement for a relocalisation")
          .text("vocabulary_file", &C::vocabulary_file,
                "vocabulary file (slamd-vocabulary writes one); empty = the one built and "
                "installed with slamd (share/slamd/orb_vocabulary.voc beside the program's "
                "bin/); a missing or corrupt file is a configuration error");
  return table;
}

BackendConfig BackendConfig::load(Config& config) {
  BackendConfig c;
  schema().load(config, c);
  return c;
}

}  // namespace slamd
