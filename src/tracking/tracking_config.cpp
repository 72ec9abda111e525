#include "slamd/tracking/tracking_config.hpp"

namespace slamd {

const char* frontEndName(FrontEndType type) {
  switch (type) {
    case FrontEndType::kOrb:
      return "orb";
    case FrontEndType::kSift:
      return "sift";
    case FrontEndType::kFovis:
      return "fovis";
  }
  return "unknown";
}

TrackingConfig TrackingConfig::load(Config& config) {
  TrackingConfig c;
  const std::string frontend =
      config.getChoice("tracking.frontend", "orb", {"orb", "sift", "fovis"});
  c.frontend = frontend == "sift"    ? FrontEndType::kSift
               : frontend == "fovis" ? FrontEndType::kFovis
                                     : FrontEndType::kOrb;
  const std::string rejection =
      config.getChoice("tracking.outlier_rejection", "auto", {"auto", "ransac", "clique"});
  c.outlier_rejection = rejection == "ransac"   ? OutlierRejection::kRansac
                        : rejection == "clique" ? OutlierRejection::kClique
                                                : OutlierRejection::kAuto;
  const std::string prior =
      config.getChoice("tracking.rotation_prior", "auto", {"auto", "on", "off"});
  c.rotation_prior = prior == "on"    ? Switch::kOn
                     : prior == "off" ? Switch::kOff
                                      : Switch::kAuto;
  c.max_features = config.getInt("tracking.max_features", c.max_features, 50, 10000);
  c.grid_cols = config.getInt("tracking.grid_cols", c.grid_cols, 1, 64);
  c.grid_rows = config.getInt("tracking.grid_rows", c.grid_rows, 1, 64);
  c.orb_levels = config.getInt("tracking.orb_levels", c.orb_levels, 1, 12);
  c.orb_fast_threshold =
      config.getInt("tracking.orb_fast_threshold", c.orb_fast_threshold, 1, 100);
  c.subpixel = config.getBool("tracking.subpixel", c.subpixel);
  c.patch_refinement = config.getBool("tracking.patch_refinement", c.patch_refinement);
  c.align_blur_sigma_px =
      config.getDouble("tracking.align_blur_sigma_px", c.align_blur_sigma_px, 0.0, 5.0);
  c.undistort = config.getBool("tracking.undistort", c.undistort);
  c.min_depth_m = config.getDouble("tracking.min_depth_m", c.min_depth_m, 0.05, 100.0);
  c.max_depth_m = config.getDouble("tracking.max_depth_m", c.max_depth_m, 0.05, 100.0);
  if (c.max_depth_m <= c.min_depth_m) {
    throw ConfigError("tracking.max_depth_m (" + std::to_string(c.max_depth_m) +
                      ") must be greater than tracking.min_depth_m (" +
                      std::to_string(c.min_depth_m) + ")");
  }
  c.match_ratio = config.getDouble("tracking.match_ratio", c.match_ratio, 0.3, 1.0);
  c.max_descriptor_distance =
      config.getInt("tracking.max_descriptor_distance", c.max_descriptor_distance, 1, 256);
  c.search_radius_px = config.getDouble("tracking.search_radius_px", c.search_radius_px, 2, 200);
  c.refine_search_radius_px =
      config.getDouble("tracking.refine_search_radius_px", c.refine_search_radius_px, 0, 50);
  c.min_guided_matches =
      config.getInt("tracking.min_guided_matches", c.min_guided_matches, 3, 10000);
  c.ransac_iterations =
      config.getInt("tracking.ransac_iterations", c.ransac_iterations, 1, 100000);
  c.inlier_threshold_px =
      config.getDouble("tracking.inlier_threshold_px", c.inlier_threshold_px, 0.1, 50);
  c.min_inliers = config.getInt("tracking.min_inliers", c.min_inliers, 3, 10000);
  c.min_features = config.getInt("tracking.min_features", c.min_features, 3, 10000);
  c.max_iterations = config.getInt("tracking.max_iterations", c.max_iterations, 1, 100);
  c.pixel_sigma_px = config.getDouble("tracking.pixel_sigma_px", c.pixel_sigma_px, 0.05, 20);
  c.depth_sigma_coeff =
      config.getDouble("tracking.depth_sigma_coeff", c.depth_sigma_coeff, 0.0, 1.0);
  c.estimate_noise_scale = config.getBool("tracking.estimate_noise_scale", c.estimate_noise_scale);
  c.huber_k = config.getDouble("tracking.huber_k", c.huber_k, 0.1, 100);
  c.joint_references = config.getInt("tracking.joint_references", c.joint_references, -1, 10);
  c.joint_max_matches =
      config.getInt("tracking.joint_max_matches", c.joint_max_matches, 10, 10000);
  c.fovis_levels = config.getInt("tracking.fovis_levels", c.fovis_levels, 1, 5);
  c.fovis_fast_threshold =
      config.getInt("tracking.fovis_fast_threshold", c.fovis_fast_threshold, 5, 100);
  c.fovis_max_sad = config.getInt("tracking.fovis_max_sad", c.fovis_max_sad, 1, 20000);
  c.fovis_clique_tolerance_m = config.getDouble("tracking.fovis_clique_tolerance_m",
                                                c.fovis_clique_tolerance_m, 0.001, 1.0);
  c.keyframe_min_inliers =
      config.getInt("tracking.keyframe_min_inliers", c.keyframe_min_inliers, 3, 10000);
  c.keyframe_min_overlap =
      config.getDouble("tracking.keyframe_min_overlap", c.keyframe_min_overlap, 0.0, 1.0);
  c.keyframe_max_translation_m = config.getDouble("tracking.keyframe_max_translation_m",
                                                  c.keyframe_max_translation_m, 0.001, 100);
  c.keyframe_max_rotation_deg = config.getDouble("tracking.keyframe_max_rotation_deg",
                                                 c.keyframe_max_rotation_deg, 0.1, 180);
  c.keyframe_window = config.getInt("tracking.keyframe_window", c.keyframe_window, 1, 1000);
  c.max_predicted_frames =
      config.getInt("tracking.max_predicted_frames", c.max_predicted_frames, 0, 1000);
  c.failure_sigma_scale =
      config.getDouble("tracking.failure_sigma_scale", c.failure_sigma_scale, 1.0, 1e6);
  return c;
}

}  // namespace slamd
