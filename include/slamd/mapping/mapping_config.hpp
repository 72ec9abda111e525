#pragma once
// Configuration of the mapping area (the `mapping.*` keys). load() throws ConfigError naming the
// key when a value is out of range, of the wrong type, or inconsistent with another option.
//
// Frames: "camera" is the optical frame of the depth image (x right, y down, z forward); "world"
// (mapping.frame_id) is the frame of T_world_camera and of the map.

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

/// How the voxel-grid filter reduces the points of one cube (texts and docs: mapping_config.cpp).
enum class VoxelFilterMode { kNearestToCentre, kCentroid };

/// How the free and occupied voxels of one frame are computed before they update the OcTree.
enum class InsertionMethod { kDenseMask, kOctomap, kOctomapDiscrete };

/// Axis of the world frame that points up, for the 2D projection.
enum class UpAxis { kPlusX, kMinusX, kPlusY, kMinusY, kPlusZ, kMinusZ };

// Each key's type, default, range, unit and doc: mapping_config.cpp (its one declaration), or
// `slamd --describe-config mapping`.
struct MappingConfig {
  // --- stage ---------------------------------------------------------------------------------
  bool enabled = true;
  bool keyframes_only = false;

  // --- OcTree and sensor model ---------------------------------------------------------------
  double resolution_m = 0.05;
  double max_range_m = 4.0;  ///< distance from the sensor origin
  double min_depth_m = 0.1;  ///< along the camera z axis
  double max_depth_m = 10.0;
  int pixel_stride = 1;
  double prob_hit = 0.7;
  double prob_miss = 0.4;
  double clamp_min = 0.12;
  double clamp_max = 0.97;
  double occupancy_threshold = 0.5;
  bool color = false;
  InsertionMethod insertion = InsertionMethod::kDenseMask;
  int prune_every_frames = 30;
  std::string frame_id = "world";

  // --- voxel-grid filter (camera frame) ------------------------------------------------------
  double voxel_filter_m = 0.05;
  VoxelFilterMode voxel_filter_mode = VoxelFilterMode::kNearestToCentre;

  // --- outputs (times are message utime, so a replayed log gives the same outputs) -----------
  double update_rate_hz = 5.0;
  bool update_new_free_voxels = true;
  double full_map_period_s = 10.0;

  // --- 2D projection for navigation (heights along the up axis from the world origin) --------
  UpAxis up_axis = UpAxis::kMinusY;
  double projection_min_height_m = -0.5;
  double projection_max_height_m = 0.5;

  // --- persistence ---------------------------------------------------------------------------
  double snapshot_period_s = 60.0;
  std::string snapshot_path;
  std::string save_prefix;
  std::string load_path;

  // --- re-integration (back end) -------------------------------------------------------------
  bool keep_keyframe_clouds = true;
  int keyframe_cloud_budget_mb = 1024;
  double keyframe_step_budget_ms = 20.0;
  int keyframe_step_points = 4000;

  // --- planes of keyframes (planes::PlaneMap), their export, and depth snapped onto them -----
  bool planes_enabled = true;
  bool planes_snap_depth = true;
  double planes_snap_sigmas = 3.0;
  double planes_max_angle_deg = 5.0;
  double planes_max_distance_m = 0.05;
  double planes_max_gap_m = 0.3;

  // --- degrading under memory pressure (daemon.memory_limit_mb) ------------------------------
  double coarse_far_radius_m = 6.0;
  int coarse_far_levels = 2;

  /// The `mapping.*` keys.
  static const ConfigSchema<MappingConfig>& schema();
  /// Reads `mapping.*`; throws ConfigError.
  static MappingConfig load(Config& config);
  /// Empty when consistent, otherwise a sentence naming the offending option (for structs built
  /// in code): every key within its range, then the checks across keys.
  std::string validationError() const;
};

const char* toString(VoxelFilterMode mode);
const char* toString(InsertionMethod method);
const char* toString(UpAxis axis);

}  // namespace slamd
