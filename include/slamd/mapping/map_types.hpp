#pragma once
// Plain data the mapper hands out: incremental updates, full binary maps and the 2D projection.
// None of these types depend on LCM; include/slamd/comms/map_codec.hpp converts them to messages.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "slamd/common/time.hpp"
#include "slamd/mapping/mapping_config.hpp"

namespace slamd {

/// One voxel whose occupancy changed (or that was first observed) since the previous update.
struct VoxelChange {
  Eigen::Vector3f center_m;  ///< voxel centre in the map frame, metres
  float log_odds = 0.0f;     ///< occupancy log-odds (> 0 occupied, < 0 free), dimensionless
};

/// The changes since the previous update (slamd.voxel_map_update_t). Updates carry absolute
/// log-odds, not increments, so applying one twice is harmless.
struct MapUpdate {
  Utime utime = 0;            ///< newest frame integrated, microseconds since the Unix epoch
  double resolution_m = 0.0;  ///< finest voxel edge, metres
  std::string frame_id;       ///< map frame
  std::int64_t sequence = 0;  ///< +1 per update; a skipped number means "resynchronise from a
                              ///< full map" (the mapper skips one after a rebuild, load or reset)
  std::vector<VoxelChange> voxels;
};

/// The complete map (slamd.voxel_map_t): OctoMap's binary stream of maximum-likelihood
/// occupancy (OcTree::writeBinaryData, the .bt body without its text header).
struct FullMap {
  Utime utime = 0;
  double resolution_m = 0.0;
  std::string frame_id;
  /// Sequence number of the first update NOT contained in this map: a subscriber that loads it
  /// continues with the update of exactly this sequence.
  std::int64_t update_sequence = 0;
  std::vector<std::uint8_t> data;
};

/// A 2D occupancy grid: the voxels overlapping a height band, projected along the up axis.
/// cells.at<uint8_t>(iy, ix) covers grid coordinates u in [origin_u + ix*res, +res) and
/// v in [origin_v + iy*res, +res); (u, v, up) is a right-handed frame made of world axes
/// (see gridAxes()). Row 0 is the lowest v (images saved by saveOccupancyGrid are flipped so
/// that +v points up, as navigation map files expect).
struct OccupancyGrid2D {
  static constexpr std::uint8_t kFree = 0;
  static constexpr std::uint8_t kOccupied = 100;
  static constexpr std::uint8_t kUnknown = 255;

  cv::Mat cells;              ///< CV_8UC1: kFree, kOccupied or kUnknown
  double resolution_m = 0.0;  ///< cell edge, metres
  double origin_u_m = 0.0;    ///< grid coordinates of the corner of cell (0, 0), metres
  double origin_v_m = 0.0;
  UpAxis up_axis = UpAxis::kMinusY;
  double min_height_m = 0.0;  ///< the band that was projected, metres along the up axis
  double max_height_m = 0.0;

  /// Cell value at grid coordinates (u, v) in metres; kUnknown outside the grid.
  std::uint8_t at(double u_m, double v_m) const;
};

/// Rows of the rotation R_grid_world: u, v and up expressed in world coordinates.
Eigen::Matrix3d gridAxes(UpAxis up_axis);

}  // namespace slamd
