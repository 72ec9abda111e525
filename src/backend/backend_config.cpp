#include "slamd/backend/backend_config.hpp"

namespace slamd {

const char* robustKernelName(RobustKernel kernel) {
  switch (kernel) {
    case RobustKernel::kNone: return "none";
    case RobustKernel::kHuber: return "huber";
    case RobustKernel::kCauchy: return "cauchy";
  }
  return "unknown";
}

BackendConfig BackendConfig::load(Config& config) {
  BackendConfig c;
  c.enabled = config.getBool("backend.enabled", c.enabled);
  const std::string kernel = config.getChoice("backend.robust_kernel", "cauchy",
                                              {"none", "huber", "cauchy"});
  c.robust_kernel = kernel == "none"    ? RobustKernel::kNone
                    : kernel == "huber" ? RobustKernel::kHuber
                                        : RobustKernel::kCauchy;
  c.robust_kernel_width =
      config.getDouble("backend.robust_kernel_width", c.robust_kernel_width, 0.01, 100.0);
  c.robust_odometry_edges =
      config.getBool("backend.robust_odometry_edges", c.robust_odometry_edges);
  c.max_iterations = config.getInt("backend.max_iterations", c.max_iterations, 1, 1000);
  c.initial_lambda = config.getDouble("backend.initial_lambda", c.initial_lambda, 1e-12, 1e6);
  c.relative_cost_tolerance = config.getDouble("backend.relative_cost_tolerance",
                                               c.relative_cost_tolerance, 0.0, 1.0);
  c.step_tolerance = config.getDouble("backend.step_tolerance", c.step_tolerance, 0.0, 1.0);
  c.odometry_sigma_ratio =
      config.getDouble("backend.odometry_sigma_ratio", c.odometry_sigma_ratio, 1e-4, 1.0);
  c.odometry_sigma_rad =
      config.getDouble("backend.odometry_sigma_rad", c.odometry_sigma_rad, 1e-5, 1.0);
  c.vocabulary_branching =
      config.getInt("backend.vocabulary_branching", c.vocabulary_branching, 2, 32);
  c.vocabulary_depth = config.getInt("backend.vocabulary_depth", c.vocabulary_depth, 1, 6);
  c.loop_min_score = config.getDouble("backend.loop_min_score", c.loop_min_score, 0.0, 1.0);
  c.loop_min_score_ratio =
      config.getDouble("backend.loop_min_score_ratio", c.loop_min_score_ratio, 0.0, 10.0);
  c.loop_exclude_recent =
      config.getInt("backend.loop_exclude_recent", c.loop_exclude_recent, 0, 100000);
  c.loop_max_candidates =
      config.getInt("backend.loop_max_candidates", c.loop_max_candidates, 1, 100);
  c.loop_min_inliers = config.getInt("backend.loop_min_inliers", c.loop_min_inliers, 6, 10000);
  c.loop_inlier_threshold_px = config.getDouble("backend.loop_inlier_threshold_px",
                                                c.loop_inlier_threshold_px, 0.5, 50.0);
  c.loop_ransac_iterations =
      config.getInt("backend.loop_ransac_iterations", c.loop_ransac_iterations, 10, 100000);
  c.loop_match_ratio =
      config.getDouble("backend.loop_match_ratio", c.loop_match_ratio, 0.3, 1.0);
  c.loop_max_descriptor_distance = config.getInt("backend.loop_max_descriptor_distance",
                                                 c.loop_max_descriptor_distance, 1, 256);
  c.align_patches = config.getBool("backend.align_patches", c.align_patches);
  c.loop_consistency = config.getInt("backend.loop_consistency", c.loop_consistency, 1, 20);
  c.loop_consistency_window =
      config.getInt("backend.loop_consistency_window", c.loop_consistency_window, 0, 1000);
  c.loop_check_odometry = config.getBool("backend.loop_check_odometry", c.loop_check_odometry);
  c.loop_max_drift_m =
      config.getDouble("backend.loop_max_drift_m", c.loop_max_drift_m, 0.0, 1000.0);
  c.loop_max_drift_ratio =
      config.getDouble("backend.loop_max_drift_ratio", c.loop_max_drift_ratio, 0.0, 10.0);
  c.local_edges = config.getInt("backend.local_edges", c.local_edges, 0, 50);
  c.local_max_candidates =
      config.getInt("backend.local_max_candidates", c.local_max_candidates, 1, 200);
  c.local_min_inliers = config.getInt("backend.local_min_inliers", c.local_min_inliers, 6, 10000);
  c.local_search_radius_px = config.getDouble("backend.local_search_radius_px",
                                              c.local_search_radius_px, 2.0, 1000.0);
  c.local_max_discrepancy_m = config.getDouble("backend.local_max_discrepancy_m",
                                               c.local_max_discrepancy_m, 0.0, 100.0);
  c.local_max_discrepancy_ratio = config.getDouble("backend.local_max_discrepancy_ratio",
                                                   c.local_max_discrepancy_ratio, 0.0, 10.0);
  c.local_max_discrepancy_rad = config.getDouble("backend.local_max_discrepancy_rad",
                                                 c.local_max_discrepancy_rad, 0.0, 3.2);
  c.local_min_sigma_m =
      config.getDouble("backend.local_min_sigma_m", c.local_min_sigma_m, 0.0, 1.0);
  c.local_min_sigma_rad =
      config.getDouble("backend.local_min_sigma_rad", c.local_min_sigma_rad, 0.0, 1.0);
  c.optimize_every_keyframe =
      config.getBool("backend.optimize_every_keyframe", c.optimize_every_keyframe);
  c.local_max_iterations =
      config.getInt("backend.local_max_iterations", c.local_max_iterations, 1, 1000);
  c.local_window_hops = config.getInt("backend.local_window_hops", c.local_window_hops, 0, 100);
  c.local_window_size =
      config.getInt("backend.local_window_size", c.local_window_size, 2, 100000);
  c.full_optimization_chi2 = config.getDouble("backend.full_optimization_chi2",
                                              c.full_optimization_chi2, 0.0, 1e12);
  c.relocalization = config.getBool("backend.relocalization", c.relocalization);
  c.relocalization_min_inliers = config.getInt("backend.relocalization_min_inliers",
                                               c.relocalization_min_inliers, 6, 10000);
  c.vocabulary_file = config.getString("backend.vocabulary_file", c.vocabulary_file);
  return c;
}

}  // namespace slamd
