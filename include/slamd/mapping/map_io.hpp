#pragma once
// File output for maps: crash-safe writes, PLY point clouds and 2D grid images.
//
// writeFileAtomically() is the basis of every file the mapper writes: the content goes to
// "<path>.tmp" in the same folder, is fsynced, renamed over <path>, and the folder is fsynced, so
// a crash or power cut at any moment leaves either the previous complete file or the new complete
// file at <path>, never a torn one. A leftover "<path>.tmp" from an interrupted write is simply
// overwritten by the next write. One writer per path at a time.

#include <cstdint>
#include <functional>
#include <ostream>
#include <string>
#include <vector>

#include <octomap/OcTree.h>

#include "slamd/common/file_io.hpp"
#include "slamd/mapping/map_types.hpp"
#include "slamd/mapping/point_cloud.hpp"

namespace slamd {

enum class PlyFormat { kAscii, kBinary };

/// Writes points (metres, any frame) with colours (BGR; white when `cloud` has none) as a PLY
/// stream with float x y z and uchar red green blue.
bool writePly(std::ostream& out, const PointCloud& cloud, PlyFormat format);

/// Reads back a PLY file written by writePly (ASCII or binary little-endian; for tests and tools).
/// Returns false on anything else.
bool readPly(const std::string& path, PointCloud& cloud);

/// Writes `tree` atomically to `path`, which ends in .bt (OctoMap's maximum-likelihood binary
/// format: leaves only, what octovis and octomap_server load) or .ot (the full tree with log-odds).
/// False with a sentence in *error for another extension or a failed write.
bool writeOcTreeFile(const octomap::OcTree& tree, const std::string& path,
                     std::string* error = nullptr);

/// The centres of the occupied leaves of `tree` (metres, the map's frame), without colours.
PointCloud occupiedVoxelCentres(const octomap::OcTree& tree);

/// Saves a grid as a navigation map: <path> ending in .pgm (binary P5) or .png, with
/// occupied = 0 (black), free = 254 (white), unknown = 205, +v up; and a sidecar YAML file
/// (<path> with the extension replaced by .yaml) in the common map_server layout (image,
/// resolution, origin [u, v, 0], negate, occupied_thresh, free_thresh). Both are written
/// atomically.
bool saveOccupancyGrid(const OccupancyGrid2D& grid, const std::string& path,
                       std::string* error = nullptr);

}  // namespace slamd
