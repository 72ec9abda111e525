#include "slamd/tracking/tracking_config.hpp"

namespace slamd {

namespace {

using C = TrackingConfig;

const EnumNames<FrontEndType> kFrontEndNames = {
    {FrontEndType::kOrb, "orb", "ORB features, Hamming matching"},
    {FrontEndType::kSift, "sift", "SIFT features, L2 matching"},
    {FrontEndType::kFovis, "fovis", "FAST corners with 9x9 patch matching, as FOVIS"},
};

const EnumNames<C::OutlierRejection> kOutlierRejectionNames = {
    {C::OutlierRejection::kAuto, "auto", "clique for fovis (as FOVIS), RANSAC for orb and sift"},
    {C::OutlierRejection::kRansac, "ransac", "RANSAC on the reprojection error"},
    {C::OutlierRejection::kClique, "clique", "maximum clique of mutually consistent 3D distances"},
};

const EnumNames<C::Switch> kSwitchNames = {
    {C::Switch::kAuto, "auto", "on for fovis only"},
    {C::Switch::kOn, "on", ""},
    {C::Switch::kOff, "off", ""},
};

}  // namespace

const char* frontEndName(FrontEndType type) { return enumText(kFrontEndNames, type); }

const ConfigSchema<TrackingConfig>& TrackingConfig::schema() {
  static const auto table =
      ConfigSchema<C>("tracking")
          .choice("frontend", &C::frontend, kFrontEndNames, "feature front end")
          .number("max_features", &C::max_features, 50, 10000, "", "features kept per frame")
          .number("grid_cols", &C::grid_cols, 1, 64, "",
                  "spatial buckets across; each bucket keeps at most max_features / (cols * "
                  "rows) of its strongest features")
          .number("grid_rows", &C::grid_rows, 1, 64, "", "spatial buckets down")
          .number("orb_levels", &C::orb_levels, 1, 12, "",
                  "ORB pyramid levels (scale 1.2); few levels halve extraction time and suffice "
                  "for fr1/xyz-like motion")
          .number("orb_fast_threshold", &C::orb_fast_threshold, 1, 100, "grey levels",
                  "ORB FAST threshold (stronger corners localise better)")
          .flag("subpixel", &C::subpixel, "refine level-0 ORB/FAST corners to sub-pixel")
          .flag("patch_refinement", &C::patch_refinement,
                "refine each inlier's position by aligning the reference image's 9x9 patch "
                "(Lucas-Kanade, translation + brightness offset), as FOVIS does; then re-estimate")
          .number("align_blur_sigma_px", &C::align_blur_sigma_px, 0.0, 5.0, "px",
                  "Gaussian blur of the images used for patch refinement (0 = none); damps "
                  "aliasing and sensor noise")
          .flag("undistort", &C::undistort,
                "undistort keypoints with the frame's plumb-bob coefficients before any geometry")
          .number("min_depth_m", &C::min_depth_m, 0.05, 100.0, "m",
                  "depth measurements below are ignored")
          .number("max_depth_m", &C::max_depth_m, 0.05, 100.0, "m",
                  "depth measurements above are ignored; > min_depth_m")
          .flag("depth_time_correction", &C::depth_time_correction,
                "when a frame's depth image was taken at another time than its colour image "
                "(Kinect v1, TUM fr1), move each feature's depth to the colour image's time "
                "under the predicted motion")
          .number("match_ratio", &C::match_ratio, 0.3, 1.0, "", "Lowe ratio, best / second")
          .number("max_descriptor_distance", &C::max_descriptor_distance, 1, 256, "bits",
                  "largest Hamming distance accepted for ORB (SIFT uses L2 < 350, FOVIS its own "
                  "SAD bound)")
          .number("search_radius_px", &C::search_radius_px, 2, 200, "px",
                  "radius of the projection-guided search around a keypoint's predicted position")
          .number("refine_search_radius_px", &C::refine_search_radius_px, 0, 50, "px",
                  "radius of the second guided search with the estimated pose (0 = off)")
          .number("min_guided_matches", &C::min_guided_matches, 3, 10000, "",
                  "fewer guided matches fall back to matching over the whole image")
          .choice("outlier_rejection", &C::outlier_rejection, kOutlierRejectionNames,
                  "how inliers are found before refinement")
          .choice("rotation_prior", &C::rotation_prior, kSwitchNames,
                  "predict the rotation by aligning 80x60 blurred images (FOVIS) instead of "
                  "constant velocity")
          .number("ransac_iterations", &C::ransac_iterations, 1, 100000, "",
                  "upper bound on RANSAC hypotheses (fewer at a high inlier ratio, 99.9% "
                  "confidence)")
          .number("inlier_threshold_px", &C::inlier_threshold_px, 0.1, 50, "px",
                  "reprojection error bound for inliers")
          .number("min_inliers", &C::min_inliers, 3, 10000, "", "fewer inliers fail the frame")
          .number("min_features", &C::min_features, 3, 10000, "",
                  "fewer features with depth fail the frame (INSUFFICIENT_FEATURES)")
          .number("max_iterations", &C::max_iterations, 1, 100, "", "Gauss-Newton/LM iterations")
          .number("pixel_sigma_px", &C::pixel_sigma_px, 0.05, 20, "px",
                  "keypoint noise at pyramid level 0 (scaled by the level's scale factor)")
          .number("depth_sigma_coeff", &C::depth_sigma_coeff, 0.0, 1.0, "1/m",
                  "depth noise sigma_z = coeff * z^2; 0 disables the depth residual")
          .flag("estimate_noise_scale", &C::estimate_noise_scale,
                "weigh reprojection and depth residuals by their estimated noise (median "
                "residual) instead of pixel_sigma_px and depth_sigma_coeff as they are")
          .number("huber_k", &C::huber_k, 0.1, 100, "sigmas", "Huber kernel width")
          .number(
              "joint_references", &C::joint_references, -1, 10, "keyframes",
              "refine the pose jointly against this many more recent keyframes (held fixed) "
              "after the keyframe; 0 = the keyframe alone; -1 = 2 for orb and sift, 0 for fovis")
          .number("joint_max_matches", &C::joint_max_matches, 10, 10000, "",
                  "matches used per extra reference in the joint refinement")
          .flag("local_map", &C::local_map,
                "after the keyframe, search the landmarks of covisible keyframes by projection "
                "(ratio test in the window, scale and orientation consistency, reprojection "
                "check) and refine the pose against all of them; replaces joint_references")
          .number("local_map_keyframes", &C::local_map_keyframes, 1, 100, "keyframes",
                  "covisible keyframes (of the last keyframe_window) whose landmarks are searched")
          .number("local_map_min_shared", &C::local_map_min_shared, 1, 1000, "landmarks",
                  "landmarks a keyframe must share with the current keyframe to be covisible")
          .number("local_map_max_matches", &C::local_map_max_matches, 10, 10000, "",
                  "local map matches kept for patch alignment and refinement (spread evenly)")
          .flag("few_inliers_previous_frame", &C::few_inliers_previous_frame,
                "a frame with fewer than keyframe_min_inliers inliers against its keyframe is "
                "refined jointly with its matches against the previous frame (held at its pose)")
          .flag("few_inliers_dense", &C::few_inliers_dense,
                "a frame with fewer than keyframe_min_inliers inliers is also aligned densely "
                "against the previous measured frame, the feature estimate as the prior "
                "(needs dense_fallback)")
          .number(
              "few_inliers_dense_max_pixels", &C::few_inliers_dense_max_pixels, 500, 100000,
              "pixels",
              "pixels per pyramid level that alignment samples (evenly); fewer cost less time but "
              "refine fewer frames")
          .number("fovis_levels", &C::fovis_levels, 1, 5, "", "FOVIS pyramid levels")
          .number("fovis_fast_threshold", &C::fovis_fast_threshold, 5, 100, "grey levels",
                  "initial FAST threshold, adapted each frame towards max_features")
          .number("fovis_max_sad", &C::fovis_max_sad, 1, 20000, "",
                  "largest sum of absolute differences of two 9x9 brightness-normalised patches "
                  "accepted as a match")
          .number("fovis_clique_tolerance_m", &C::fovis_clique_tolerance_m, 0.001, 1.0, "m",
                  "two matches are consistent when their 3D distances differ by less than this "
                  "plus both points' depth noise")
          .number("keyframe_min_inliers", &C::keyframe_min_inliers, 3, 10000, "",
                  "fewer inliers against the keyframe make the current frame a keyframe")
          .number("keyframe_min_overlap", &C::keyframe_min_overlap, 0.0, 1.0, "fraction",
                  "fraction of the keyframe's features with depth still tracked; below it the "
                  "current frame becomes a keyframe")
          .number("keyframe_max_baseline_ratio", &C::keyframe_max_baseline_ratio, 0.001, 100.0, "",
                  "farther from the keyframe than this times its median feature depth makes "
                  "a new keyframe (parallax: near scenes change faster)")
          .number("keyframe_max_translation_m", &C::keyframe_max_translation_m, 0.001, 100, "m",
                  "farther from the keyframe makes a new keyframe (a safety bound: novelty, the "
                  "overlap and inlier rules, usually comes first)")
          .number("keyframe_max_rotation_deg", &C::keyframe_max_rotation_deg, 0.1, 180, "deg",
                  "more rotation from the keyframe makes a new keyframe (a safety bound, as the "
                  "distance)")
          .number("keyframe_window", &C::keyframe_window, 1, 1000, "keyframes",
                  "recent keyframes kept (about 3 MB each at 640x480); a due keyframe re-uses a "
                  "recent one near the current pose if it tracks well (1 = never re-use)")
          .flag("map_keyframes", &C::map_keyframes,
                "a due keyframe also tries the back end's keyframes near the current pose (the "
                "map's view of the place, kept after culling) before a new one is made")
          .number("max_predicted_frames", &C::max_predicted_frames, 0, 1000, "frames",
                  "consecutive failed frames bridged by constant-velocity prediction before LOST")
          .number("relocalization_keyframes", &C::relocalization_keyframes, 0, 1000, "keyframes",
                  "after LOST, the first trackable frame is matched against this many of the "
                  "most recent keyframes before it starts a new segment (0 = always a new "
                  "segment)")
          .number("relocalization_min_inliers", &C::relocalization_min_inliers, 3, 100000, "",
                  "inliers a match against a keyframe needs to relocalise after LOST (the pose "
                  "must also be within the motion limits since the last measured frame)")
          .number("relocalization_keyframe_interval_s", &C::relocalization_keyframe_interval_s, 0.0,
                  3600.0, "s",
                  "while the back end has not placed the segment in its map, a frame whose view "
                  "changed (relocalization_keyframe_novelty) becomes a keyframe, and so a "
                  "relocalisation attempt, this long after the last keyframe; each further one "
                  "of the segment waits twice as long (0 = only the usual keyframes)")
          .number("relocalization_keyframe_max_interval_s",
                  &C::relocalization_keyframe_max_interval_s, 0.0, 3600.0, "s",
                  "the longest such a wait grows (a segment that never joins the map then adds "
                  "at most one keyframe this often for relocalisation)")
          .number("relocalization_keyframe_novelty", &C::relocalization_keyframe_novelty, 0.0, 1.0,
                  "fraction",
                  "how far the view must have changed for such a keyframe, as a fraction of the "
                  "keyframe bounds (distance, rotation, and lost overlap)")
          .number("failure_sigma_scale", &C::failure_sigma_scale, 1.0, 1e6, "",
                  "covariance inflation of a predicted (failed) frame relative to the last good "
                  "frame's")
          .flag("dense_fallback", &C::dense_fallback,
                "when features cannot measure a frame, align it densely (photometric + "
                "point-to-plane on every pixel, coarse to fine) to the last measured frame "
                "before falling back to prediction")
          .number("dense_levels", &C::dense_levels, 2, 6, "",
                  "pyramid levels of dense alignment (each halves the resolution)")
          .number("dense_finest_level", &C::dense_finest_level, 0, 5, "",
                  "finest pyramid level aligned (0 = full resolution, 1 = half); < dense_levels")
          .number("dense_min_gradient", &C::dense_min_gradient, 0.0, 255.0, "grey levels/px",
                  "pixels with a weaker image gradient carry no photometric residual")
          .number("dense_min_coarse_gradient_share", &C::dense_min_coarse_gradient_share, 0.0, 1.0,
                  "",
                  "a pyramid level coarser than the finest aligns its grey image only when the "
                  "weaker axis of its photometric pixels' gradient scatter holds at least this "
                  "share (two orientations); below, depth alone aligns it (one edge and a few "
                  "specks, downsampled, pull the estimate centimetres off: docs/planes.md). 0 = "
                  "the grey image at every level")
          .number("dense_min_gradient_share", &C::dense_min_gradient_share, 0.0, 0.5, "",
                  "when the weaker axis of the photometric pixels' gradient scatter holds less "
                  "than this share of it (one straight edge with its ends and a few specks), the "
                  "image motion along that axis is not measured (the aperture problem); 0 = off "
                  "(docs/planes.md: what 0.05 did on plain corridors)")
          .number("motion_prior_sigma_mps", &C::motion_prior_sigma_mps, 0.001, 100.0, "m/s",
                  "uncertainty of the constant-velocity prior's speed: the prior's translation "
                  "sigma is this times the time since the last measured frame. Dense alignment's "
                  "prior (a direction the scene leaves free, along a plain corridor, keeps the "
                  "prior and this uncertainty) and the disagreement gate's")
          .number("motion_prior_sigma_degps", &C::motion_prior_sigma_degps, 0.01, 10000.0, "deg/s",
                  "the same for the rotation rate")
          .number("motion_prior_gate_sigma", &C::motion_prior_gate_sigma, 0.0, 1000.0, "sigma",
                  "a feature estimate further than this from the constant-velocity prediction "
                  "(Mahalanobis distance, prior and estimate covariance combined) is rejected and "
                  "tracking retried, as for the motion limits; 0 = off");
  return table;
}

TrackingConfig TrackingConfig::load(Config& config) {
  TrackingConfig c;
  schema().load(config, c);
  c.motion_limits = MotionLimits::load(config);
  if (c.dense_finest_level >= c.dense_levels) {
    throw ConfigError("tracking.dense_finest_level (" + std::to_string(c.dense_finest_level) +
                      ") must be less than tracking.dense_levels (" +
                      std::to_string(c.dense_levels) + ")");
  }
  if (c.max_depth_m <= c.min_depth_m) {
    throw ConfigError("tracking.max_depth_m (" + std::to_string(c.max_depth_m) +
                      ") must be greater than tracking.min_depth_m (" +
                      std::to_string(c.min_depth_m) + ")");
  }
  return c;
}

}  // namespace slamd
