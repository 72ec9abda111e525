#include "slamd/mapping/mapping_config.hpp"

#include <sstream>

namespace slamd {

namespace {

VoxelFilterMode parseFilterMode(const std::string& text) {
  return text == "centroid" ? VoxelFilterMode::kCentroid : VoxelFilterMode::kNearestToCentre;
}

InsertionMethod parseInsertion(const std::string& text) {
  if (text == "octomap") return InsertionMethod::kOctomap;
  if (text == "octomap_discrete") return InsertionMethod::kOctomapDiscrete;
  return InsertionMethod::kDenseMask;
}

UpAxis parseUpAxis(const std::string& text) {
  if (text == "+x") return UpAxis::kPlusX;
  if (text == "-x") return UpAxis::kMinusX;
  if (text == "+y") return UpAxis::kPlusY;
  if (text == "+z") return UpAxis::kPlusZ;
  if (text == "-z") return UpAxis::kMinusZ;
  return UpAxis::kMinusY;
}

}  // namespace

const char* toString(VoxelFilterMode mode) {
  return mode == VoxelFilterMode::kCentroid ? "centroid" : "nearest";
}

const char* toString(InsertionMethod method) {
  switch (method) {
    case InsertionMethod::kOctomap:
      return "octomap";
    case InsertionMethod::kOctomapDiscrete:
      return "octomap_discrete";
    case InsertionMethod::kDenseMask:
      break;
  }
  return "dense";
}

const char* toString(UpAxis axis) {
  switch (axis) {
    case UpAxis::kPlusX:
      return "+x";
    case UpAxis::kMinusX:
      return "-x";
    case UpAxis::kPlusY:
      return "+y";
    case UpAxis::kPlusZ:
      return "+z";
    case UpAxis::kMinusZ:
      return "-z";
    case UpAxis::kMinusY:
      break;
  }
  return "-y";
}

MappingConfig MappingConfig::load(Config& config) {
  MappingConfig c;
  c.resolution_m = config.getDouble("mapping.resolution_m", c.resolution_m, 0.005, 1.0);
  c.max_range_m = config.getDouble("mapping.max_range_m", c.max_range_m, 0.1, 100.0);
  c.min_depth_m = config.getDouble("mapping.min_depth_m", c.min_depth_m, 0.0, 10.0);
  c.max_depth_m = config.getDouble("mapping.max_depth_m", c.max_depth_m, 0.1, 100.0);
  c.pixel_stride = config.getInt("mapping.pixel_stride", c.pixel_stride, 1, 16);
  c.prob_hit = config.getDouble("mapping.prob_hit", c.prob_hit, 0.51, 0.999);
  c.prob_miss = config.getDouble("mapping.prob_miss", c.prob_miss, 0.001, 0.49);
  c.clamp_min = config.getDouble("mapping.clamp_min", c.clamp_min, 0.001, 0.49);
  c.clamp_max = config.getDouble("mapping.clamp_max", c.clamp_max, 0.51, 0.999);
  c.occupancy_threshold =
      config.getDouble("mapping.occupancy_threshold", c.occupancy_threshold, 0.01, 0.99);
  c.color = config.getBool("mapping.color", c.color);
  c.insertion = parseInsertion(config.getChoice("mapping.insertion", toString(c.insertion),
                                                {"dense", "octomap", "octomap_discrete"}));
  c.prune_every_frames =
      config.getInt("mapping.prune_every_frames", c.prune_every_frames, 0, 100000);
  c.frame_id = config.getString("mapping.frame_id", c.frame_id);
  c.voxel_filter_m = config.getDouble("mapping.voxel_filter_m", c.voxel_filter_m, 0.0, 1.0);
  c.voxel_filter_mode = parseFilterMode(config.getChoice(
      "mapping.voxel_filter_mode", toString(c.voxel_filter_mode), {"nearest", "centroid"}));
  c.update_rate_hz = config.getDouble("mapping.update_rate_hz", c.update_rate_hz, 0.0, 1000.0);
  c.update_new_free_voxels =
      config.getBool("mapping.update_new_free_voxels", c.update_new_free_voxels);
  c.full_map_period_s =
      config.getDouble("mapping.full_map_period_s", c.full_map_period_s, 0.0, 86400.0);
  c.up_axis = parseUpAxis(config.getChoice("mapping.projection.up_axis", toString(c.up_axis),
                                           {"+x", "-x", "+y", "-y", "+z", "-z"}));
  c.projection_min_height_m = config.getDouble("mapping.projection.min_height_m",
                                               c.projection_min_height_m, -100.0, 100.0);
  c.projection_max_height_m = config.getDouble("mapping.projection.max_height_m",
                                               c.projection_max_height_m, -100.0, 100.0);
  c.snapshot_period_s =
      config.getDouble("mapping.snapshot_period_s", c.snapshot_period_s, 0.0, 86400.0);
  c.snapshot_path = config.getString("mapping.snapshot_path", c.snapshot_path);
  c.save_prefix = config.getString("mapping.save_prefix", c.save_prefix);
  c.load_path = config.getString("mapping.load_path", c.load_path);
  c.keep_keyframe_clouds = config.getBool("mapping.keep_keyframe_clouds", c.keep_keyframe_clouds);
  c.keyframe_cloud_budget_mb =
      config.getInt("mapping.keyframe_cloud_budget_mb", c.keyframe_cloud_budget_mb, 1, 65536);
  if (const std::string error = c.validationError(); !error.empty()) throw ConfigError(error);
  return c;
}

std::string MappingConfig::validationError() const {
  std::ostringstream out;
  const auto in = [](double v, double lo, double hi) { return v >= lo && v <= hi; };
  if (!in(resolution_m, 0.005, 1.0)) {
    out << "mapping.resolution_m = " << resolution_m << ": allowed 0.005..1 metres";
  } else if (!in(max_range_m, 0.1, 100.0)) {
    out << "mapping.max_range_m = " << max_range_m << ": allowed 0.1..100 metres";
  } else if (!in(min_depth_m, 0.0, 10.0) || !in(max_depth_m, 0.1, 100.0) ||
             min_depth_m > max_depth_m) {
    out << "mapping.min_depth_m = " << min_depth_m << ", mapping.max_depth_m = " << max_depth_m
        << ": need 0 <= min_depth_m <= max_depth_m <= 100 metres";
  } else if (pixel_stride < 1 || pixel_stride > 16) {
    out << "mapping.pixel_stride = " << pixel_stride << ": allowed 1..16";
  } else if (!in(prob_hit, 0.51, 0.999) || !in(prob_miss, 0.001, 0.49)) {
    out << "mapping.prob_hit = " << prob_hit << ", mapping.prob_miss = " << prob_miss
        << ": need prob_hit in 0.51..0.999 and prob_miss in 0.001..0.49";
  } else if (!in(clamp_min, 0.001, 0.49) || !in(clamp_max, 0.51, 0.999)) {
    out << "mapping.clamp_min = " << clamp_min << ", mapping.clamp_max = " << clamp_max
        << ": need clamp_min in 0.001..0.49 and clamp_max in 0.51..0.999";
  } else if (!(occupancy_threshold > clamp_min && occupancy_threshold < clamp_max)) {
    out << "mapping.occupancy_threshold = " << occupancy_threshold
        << ": must lie strictly between mapping.clamp_min = " << clamp_min
        << " and mapping.clamp_max = " << clamp_max;
  } else if (!in(voxel_filter_m, 0.0, 1.0)) {
    out << "mapping.voxel_filter_m = " << voxel_filter_m << ": allowed 0..1 metres";
  } else if (!in(update_rate_hz, 0.0, 1000.0) || !in(full_map_period_s, 0.0, 86400.0) ||
             !in(snapshot_period_s, 0.0, 86400.0)) {
    out << "mapping.update_rate_hz / full_map_period_s / snapshot_period_s out of range";
  } else if (!(projection_min_height_m < projection_max_height_m) ||
             !in(projection_min_height_m, -100.0, 100.0) ||
             !in(projection_max_height_m, -100.0, 100.0)) {
    out << "mapping.projection.min_height_m = " << projection_min_height_m
        << " must be below mapping.projection.max_height_m = " << projection_max_height_m
        << " (both within -100..100 metres)";
  } else if (prune_every_frames < 0) {
    out << "mapping.prune_every_frames = " << prune_every_frames << ": must be >= 0";
  } else if (keyframe_cloud_budget_mb < 1 || keyframe_cloud_budget_mb > 65536) {
    out << "mapping.keyframe_cloud_budget_mb = " << keyframe_cloud_budget_mb
        << ": allowed 1..65536";
  } else if (frame_id.empty()) {
    out << "mapping.frame_id must not be empty";
  }
  return out.str();
}

}  // namespace slamd
