#pragma once
// Configuration of the mapping area (the `mapping.*` keys). Every option lists its type, default,
// allowed range and unit. load() throws ConfigError naming the key when a value is out of range,
// of the wrong type, or inconsistent with another option.
//
// Frames: "camera" is the optical frame of the depth image (x right, y down, z forward); "world"
// (mapping.frame_id) is the frame of T_world_camera and of the map.

#include <string>

#include "slamd/common/config.hpp"

namespace slamd {

enum class VoxelFilterMode {
  kNearestToCentre,  ///< keep the measured point nearest the voxel centre (paper 002)
  kCentroid,         ///< replace the voxel's points by their mean (colour averaged too)
};

/// How the free and occupied voxels of one frame are computed before they update the OcTree.
enum class InsertionMethod {
  kDenseMask,        ///< slamd's default: rays cast with OcTree::computeRayKeys, voxels
                     ///< de-duplicated in a dense bit mask over the frame's key bounding box
  kOctomap,          ///< OcTree::insertPointCloud (KeySet hashing), the reference
  kOctomapDiscrete,  ///< OcTree::insertPointCloud with discretize = true
};

/// Axis of the world frame that points up, for the 2D projection.
enum class UpAxis { kPlusX, kMinusX, kPlusY, kMinusY, kPlusZ, kMinusZ };

struct MappingConfig {
  // --- OcTree and sensor model ---------------------------------------------------------------
  /// `resolution_m` (double, default 0.05, 0.005..1, metres): edge of the finest OcTree voxel.
  double resolution_m = 0.05;
  /// `max_range_m` (double, default 4, 0.1..100, metres, distance from the sensor origin): longer
  /// rays clear free space up to this distance and mark no occupied endpoint.
  double max_range_m = 4.0;
  /// `min_depth_m` (double, default 0.1, 0..10, metres along the camera z axis): closer
  /// measurements are dropped (counted as out of range).
  double min_depth_m = 0.1;
  /// `max_depth_m` (double, default 10, 0.1..100, metres along the camera z axis): farther
  /// measurements are treated as invalid and dropped; must be >= min_depth_m.
  double max_depth_m = 10.0;
  /// `pixel_stride` (int, default 1, 1..16, pixels): use every n-th pixel in x and y.
  int pixel_stride = 1;
  /// `prob_hit` (double, default 0.7, 0.51..0.999, probability): sensor model for an endpoint.
  double prob_hit = 0.7;
  /// `prob_miss` (double, default 0.4, 0.001..0.49, probability): sensor model along a ray.
  double prob_miss = 0.4;
  /// `clamp_min` (double, default 0.12, 0.001..0.49, probability): lower clamping bound.
  double clamp_min = 0.12;
  /// `clamp_max` (double, default 0.97, 0.51..0.999, probability): upper clamping bound.
  double clamp_max = 0.97;
  /// `occupancy_threshold` (double, default 0.5, 0.01..0.99, probability): a voxel is occupied
  /// above it; must lie strictly between clamp_min and clamp_max.
  double occupancy_threshold = 0.5;
  /// `color` (bool, default false): keep a colour per voxel (octomap::ColorOcTree).
  bool color = false;
  /// `insertion` (choice dense|octomap|octomap_discrete, default dense): see InsertionMethod.
  InsertionMethod insertion = InsertionMethod::kDenseMask;
  /// `prune_every_frames` (int, default 30, 0..100000, frames): compress the tree (OcTree::prune)
  /// every n integrated frames; 0 = only before saving and publishing full maps.
  int prune_every_frames = 30;
  /// `frame_id` (string, default "world"): name of the map frame in messages.
  std::string frame_id = "world";

  // --- voxel-grid filter (camera frame) ------------------------------------------------------
  /// `voxel_filter_m` (double, default 0.05, 0..1, metres, camera frame): edge of the filter's
  /// cubes; 0 disables the filter.
  double voxel_filter_m = 0.05;
  /// `voxel_filter_mode` (choice nearest|centroid, default nearest): see VoxelFilterMode.
  VoxelFilterMode voxel_filter_mode = VoxelFilterMode::kNearestToCentre;

  // --- outputs (times are message utime, so a replayed log gives the same outputs) -----------
  /// `update_rate_hz` (double, default 5, 0..1000, hertz): voxel_map_update_t rate; 0 = none.
  double update_rate_hz = 5.0;
  /// `update_new_free_voxels` (bool, default true): include newly observed free voxels in
  /// updates. false sends only occupied voxels and occupancy flips: a subscriber's occupied set
  /// stays exact while exploration updates shrink several-fold, but its free space stays unknown
  /// until the next full map.
  bool update_new_free_voxels = true;
  /// `full_map_period_s` (double, default 10, 0..86400, seconds): full voxel_map_t period;
  /// 0 = only on request.
  double full_map_period_s = 10.0;

  // --- 2D projection for navigation ----------------------------------------------------------
  /// `projection.up_axis` (choice +x|-x|+y|-y|+z|-z, default -y): world axis pointing up. The
  /// default suits a world frame equal to the first camera's optical frame held level (y down).
  UpAxis up_axis = UpAxis::kMinusY;
  /// `projection.min_height_m`, `projection.max_height_m` (double, defaults -0.5 / 0.5,
  /// -100..100, metres along the up axis from the world origin): only voxels overlapping this
  /// band are projected; min must be below max.
  double projection_min_height_m = -0.5;
  double projection_max_height_m = 0.5;

  // --- persistence ---------------------------------------------------------------------------
  /// `snapshot_period_s` (double, default 60, 0..86400, seconds): crash-safe snapshot period;
  /// 0 = no periodic snapshots.
  double snapshot_period_s = 60.0;
  /// `snapshot_path` (string, default "": none): snapshot file, .ot (full probabilities) or .bt
  /// (maximum-likelihood binary); written to a temporary file in the same folder, fsynced, then
  /// renamed over the previous snapshot.
  std::string snapshot_path;
  /// `save_prefix` (string, default "": none): SAVE_MAP and shutdown write <prefix>.bt and
  /// <prefix>.ot (the daemon may also pass its own path).
  std::string save_prefix;
  /// `load_path` (string, default "": start empty): a .bt or .ot map to continue mapping from.
  std::string load_path;

  // --- re-integration (back end) -------------------------------------------------------------
  /// `keep_keyframe_clouds` (bool, default true): keep each keyframe's filtered camera-frame cloud
  /// so the map can be rebuilt when keyframe poses are corrected.
  bool keep_keyframe_clouds = true;
  /// `keyframe_cloud_budget_mb` (int, default 1024, 1..65536, mebibytes): memory the kept clouds
  /// may use; beyond it new keyframe clouds are not kept (counted).
  int keyframe_cloud_budget_mb = 1024;

  /// Reads `mapping.*`; throws ConfigError.
  static MappingConfig load(Config& config);
  /// Empty when consistent, otherwise a sentence naming the offending option (for structs built
  /// in code).
  std::string validationError() const;
};

const char* toString(VoxelFilterMode mode);
const char* toString(InsertionMethod method);
const char* toString(UpAxis axis);

}  // namespace slamd
