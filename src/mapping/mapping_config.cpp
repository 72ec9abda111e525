#include "slamd/mapping/mapping_config.hpp"

#include <sstream>

namespace slamd {

namespace {

const EnumNames<VoxelFilterMode> kVoxelFilterModeNames = {
    {VoxelFilterMode::kNearestToCentre, "nearest",
     "keep the measured point nearest the cube's centre (paper 002)"},
    {VoxelFilterMode::kCentroid, "centroid",
     "replace the cube's points by their mean (colour averaged too)"},
};

const EnumNames<InsertionMethod> kInsertionMethodNames = {
    {InsertionMethod::kDenseMask, "dense",
     "rays cast with OcTree::computeRayKeys, voxels de-duplicated in a dense bit mask over the "
     "frame's key bounding box"},
    {InsertionMethod::kOctomap, "octomap",
     "OcTree::insertPointCloud (KeySet hashing), the reference"},
    {InsertionMethod::kOctomapDiscrete, "octomap_discrete",
     "OcTree::insertPointCloud with discretize = true"},
};

const EnumNames<UpAxis> kUpAxisNames = {
    {UpAxis::kPlusX, "+x", ""},  {UpAxis::kMinusX, "-x", ""}, {UpAxis::kPlusY, "+y", ""},
    {UpAxis::kMinusY, "-y", ""}, {UpAxis::kPlusZ, "+z", ""},  {UpAxis::kMinusZ, "-z", ""},
};

}  // namespace

const char* toString(VoxelFilterMode mode) { return enumText(kVoxelFilterModeNames, mode); }
const char* toString(InsertionMethod method) { return enumText(kInsertionMethodNames, method); }
const char* toString(UpAxis axis) { return enumText(kUpAxisNames, axis); }

const ConfigSchema<MappingConfig>& MappingConfig::schema() {
  using C = MappingConfig;
  static const auto table =
      ConfigSchema<C>("mapping")
          .flag("enabled", &C::enabled, "run the mapping stage (voxel filter + OctoMap)")
          .flag("keyframes_only", &C::keyframes_only,
                "integrate only keyframes instead of every tracked frame (less CPU, sparser free "
                "space)")
          .number("resolution_m", &C::resolution_m, 0.005, 1.0, "m",
                  "edge of the finest OcTree voxel")
          .number("max_range_m", &C::max_range_m, 0.1, 100.0, "m",
                  "longer rays (from the sensor origin) clear free space up to this distance and "
                  "mark no occupied endpoint")
          .number("min_depth_m", &C::min_depth_m, 0.0, 10.0, "m",
                  "closer measurements (camera z) are dropped, counted as out of range")
          .number("max_depth_m", &C::max_depth_m, 0.1, 100.0, "m",
                  "farther measurements (camera z) are invalid and dropped; >= min_depth_m")
          .number("pixel_stride", &C::pixel_stride, 1, 16, "px", "use every n-th pixel in x and y")
          .number("prob_hit", &C::prob_hit, 0.51, 0.999, "probability",
                  "sensor model for an endpoint")
          .number("prob_miss", &C::prob_miss, 0.001, 0.49, "probability",
                  "sensor model along a ray")
          .number("clamp_min", &C::clamp_min, 0.001, 0.49, "probability", "lower clamping bound")
          .number("clamp_max", &C::clamp_max, 0.51, 0.999, "probability", "upper clamping bound")
          .number("occupancy_threshold", &C::occupancy_threshold, 0.01, 0.99, "probability",
                  "a voxel is occupied above it; strictly between clamp_min and clamp_max")
          .flag("color", &C::color, "keep a colour per voxel (octomap::ColorOcTree)")
          .choice("insertion", &C::insertion, kInsertionMethodNames,
                  "how a frame's free and occupied voxels are computed before they update the "
                  "OcTree")
          .number("prune_every_frames", &C::prune_every_frames, 0, 100000, "frames",
                  "compress the tree (OcTree::prune) every n integrated frames; 0 = only before "
                  "saving and publishing full maps")
          .text("frame_id", &C::frame_id, "name of the map frame in messages; not empty")
          .number("voxel_filter_m", &C::voxel_filter_m, 0.0, 1.0, "m",
                  "edge of the voxel-grid filter's cubes (camera frame); 0 disables the filter")
          .choice("voxel_filter_mode", &C::voxel_filter_mode, kVoxelFilterModeNames,
                  "how the filter reduces the points of one cube")
          .number("update_rate_hz", &C::update_rate_hz, 0.0, 1000.0, "Hz",
                  "voxel_map_update_t rate; 0 = none")
          .flag("update_new_free_voxels", &C::update_new_free_voxels,
                "include newly observed free voxels in updates; false sends only occupied voxels "
                "and occupancy flips (updates shrink several-fold, a subscriber's free space stays "
                "unknown until the next full map)")
          .number("full_map_period_s", &C::full_map_period_s, 0.0, 86400.0, "s",
                  "full voxel_map_t period; 0 = only on request")
          .choice("projection.up_axis", &C::up_axis, kUpAxisNames,
                  "world axis pointing up, for the 2D projection; -y suits a world frame equal to "
                  "the first camera's optical frame held level")
          .number("projection.min_height_m", &C::projection_min_height_m, -100.0, 100.0, "m",
                  "only voxels overlapping [min_height_m, max_height_m] along the up axis are "
                  "projected; below max_height_m")
          .number("projection.max_height_m", &C::projection_max_height_m, -100.0, 100.0, "m",
                  "upper end of the projected band")
          .number("snapshot_period_s", &C::snapshot_period_s, 0.0, 86400.0, "s",
                  "crash-safe snapshot period; 0 = no periodic snapshots")
          .text("snapshot_path", &C::snapshot_path,
                "snapshot file, .ot (full probabilities) or .bt (maximum likelihood), written to a "
                "temporary file in the same folder, fsynced, renamed; empty = none")
          .text("save_prefix", &C::save_prefix,
                "SAVE_MAP and shutdown write <prefix>.bt and <prefix>.ot; empty = none")
          .text("load_path", &C::load_path,
                "a .bt or .ot map to continue mapping from; empty = start empty")
          .flag("keep_keyframe_clouds", &C::keep_keyframe_clouds,
                "with the back end on: the map is made of keyframes, whose filtered clouds are "
                "kept so that corrections move them (log-odds unclamped, so that a keyframe's "
                "contribution can be taken out exactly); false maps frames where they were first "
                "put. Off when the back end is off")
          .number("keyframe_cloud_budget_mb", &C::keyframe_cloud_budget_mb, 1, 65536, "MiB",
                  "memory the kept clouds may use; beyond it new clouds are not kept (counted) "
                  "and corrections do not move them")
          .number("keyframe_step_budget_ms", &C::keyframe_step_budget_ms, 0.0, 10000.0, "ms",
                  "the mapping stage's time per frame: kept keyframes go in, and keyframes a "
                  "correction moved move, in what the frame left of it, a step (a part taken out "
                  "or put in) at a time, at least one step when anything is left")
          .number("keyframe_step_points", &C::keyframe_step_points, 100, 10000000, "points",
                  "a kept keyframe cloud goes into the map, and moves, in parts of this many "
                  "points (bands of the image), a step each")
          .flag("planes.enabled", &C::planes_enabled,
                "segment each keyframe into planes (4 ms each) in the mapping thread and fuse "
                "them into the map's planes, which follow the back end's corrections: published "
                "on channels.plane_map and written beside a saved map as <map>.planes.ply")
          .flag("planes.snap_depth", &C::planes_snap_depth,
                "with planes.enabled: a keyframe's depth on a plane is replaced by where the "
                "pixel's ray meets the plane (within planes.snap_sigmas), so the map's walls and "
                "floors lose the depth noise across them")
          .number("planes.snap_sigmas", &C::planes_snap_sigmas, 0.5, 10.0, "sigma",
                  "a pixel is snapped onto its plane only when its depth is within this many "
                  "standard deviations of the Kinect v1 depth noise of the plane's depth there")
          .number("planes.max_angle_deg", &C::planes_max_angle_deg, 0.1, 45.0, "deg",
                  "a keyframe's plane joins a map plane only when their normals are within this")
          .number("planes.max_distance_m", &C::planes_max_distance_m, 0.001, 1.0, "m",
                  "... and its centroid lies within this of the map plane")
          .number("planes.max_gap_m", &C::planes_max_gap_m, 0.0, 10.0, "m",
                  "... and its outline overlaps the map plane's polygon or lies within this of it "
                  "(in the plane)")
          .number("coarse_far_radius_m", &C::coarse_far_radius_m, 0.0, 1000.0, "m",
                  "over the memory limit, the map farther than this from the camera is made "
                  "coarser (see coarse_far_levels); what the camera sees stays at full resolution "
                  "when it exceeds max_range_m")
          .number("coarse_far_levels", &C::coarse_far_levels, 0, 4, "levels",
                  "over the memory limit, far voxels are merged up to this many OcTree levels (2 "
                  "= blocks of 4x4x4 voxels): a block is occupied where any of its voxels was, "
                  "free only where all were free, and left fine where free meets unknown; 0 = "
                  "never");
  return table;
}

MappingConfig MappingConfig::load(Config& config) {
  MappingConfig c;
  schema().load(config, c);
  if (const std::string error = c.validationError(); !error.empty()) throw ConfigError(error);
  return c;
}

std::string MappingConfig::validationError() const {
  if (std::string error = schema().rangeError(*this); !error.empty()) return error;
  std::ostringstream out;
  if (min_depth_m > max_depth_m) {
    out << "mapping.min_depth_m = " << min_depth_m << ", mapping.max_depth_m = " << max_depth_m
        << ": need 0 <= min_depth_m <= max_depth_m <= 100 metres";
  } else if (!(occupancy_threshold > clamp_min && occupancy_threshold < clamp_max)) {
    out << "mapping.occupancy_threshold = " << occupancy_threshold
        << ": must lie strictly between mapping.clamp_min = " << clamp_min
        << " and mapping.clamp_max = " << clamp_max;
  } else if (!(projection_min_height_m < projection_max_height_m)) {
    out << "mapping.projection.min_height_m = " << projection_min_height_m
        << " must be below mapping.projection.max_height_m = " << projection_max_height_m
        << " (both within -100..100 metres)";
  } else if (frame_id.empty()) {
    out << "mapping.frame_id must not be empty";
  }
  return out.str();
}

}  // namespace slamd
