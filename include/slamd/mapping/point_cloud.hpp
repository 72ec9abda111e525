#pragma once
// Point clouds for mapping: depth image to camera-frame cloud, and the voxel-grid filter.
//
// Usage (one thread; both steps reuse their buffers across frames):
//   PointCloud cloud;
//   DepthCloudStats stats;
//   depthToCloud(frame.depth_m, frame.color_bgr, frame.intrinsics, options, cloud, stats);
//   VoxelGridFilter filter;
//   PointCloud filtered;
//   filter.apply(cloud, 0.05, VoxelFilterMode::kNearestToCentre, filtered);
//
// Frame convention: depthToCloud produces points in the camera optical frame (x right, y down,
// z forward, metres). The filter works in whatever frame its input is in; its grid is aligned to
// that frame's origin.

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/mapping/mapping_config.hpp"

namespace slamd {

using ColorBgr = std::array<std::uint8_t, 3>;  ///< blue, green, red in 0..255

/// Points (metres, frame named by the owner) and optional per-point colours.
struct PointCloud {
  std::vector<Eigen::Vector3f> points;
  std::vector<ColorBgr> colors_bgr;  ///< empty, or one per point

  std::size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  bool hasColor() const { return !colors_bgr.empty(); }
  void clear() {
    points.clear();
    colors_bgr.clear();
  }
  /// Heap bytes held by the cloud (for memory budgets).
  std::size_t memoryBytes() const {
    return points.capacity() * sizeof(Eigen::Vector3f) + colors_bgr.capacity() * sizeof(ColorBgr);
  }
};

struct DepthToCloudOptions {
  double min_depth_m = 0.1;   ///< camera z, metres: closer samples are dropped
  double max_depth_m = 10.0;  ///< camera z, metres: farther samples are dropped
  int pixel_stride = 1;       ///< use every n-th pixel along x and y (>= 1)
};

/// Why each sampled pixel was or was not turned into a point.
struct DepthCloudStats {
  std::int64_t sampled = 0;   ///< pixels visited (after the stride)
  std::int64_t valid = 0;     ///< points produced
  std::int64_t nan = 0;       ///< NaN depth (no measurement)
  std::int64_t infinite = 0;  ///< +/-inf depth
  std::int64_t zero = 0;      ///< exactly 0 (no measurement in raw sensor units)
  std::int64_t negative = 0;  ///< below 0
  std::int64_t too_near = 0;  ///< 0 < depth < min_depth_m
  std::int64_t too_far = 0;   ///< depth > max_depth_m
  bool color_used = false;    ///< colour attached (CV_8UC3 of the depth image's size)

  std::int64_t rejected() const { return nan + infinite + zero + negative + too_near + too_far; }
};

enum class DepthCloudStatus {
  kOk,
  kBadDepthType,   ///< depth is not CV_32FC1 (or is empty)
  kSizeMismatch,   ///< depth size differs from the intrinsics' width x height
  kBadIntrinsics,  ///< non-finite or non-positive focal lengths, non-finite principal point
  kBadOptions,     ///< stride < 1 or depth limits not finite / ordered
};

const char* toString(DepthCloudStatus status);

/// Back-projects every valid depth pixel (z = depth_m, metres) into the camera optical frame.
/// NaN, infinite, zero, negative and out-of-range depths never produce points; they are counted
/// in `stats`. Colour (CV_8UC3 BGR of the same size) is attached when present; otherwise the
/// cloud has no colours. `cloud` is cleared first; on a non-kOk status it stays empty.
DepthCloudStatus depthToCloud(const cv::Mat& depth_m, const cv::Mat& color_bgr,
                              const CameraIntrinsics& intrinsics,
                              const DepthToCloudOptions& options, PointCloud& cloud,
                              DepthCloudStats& stats);

/// Voxel-grid down-sampling with an open-addressing hash on the integer cube coordinates:
/// linear in the number of points, output order = order in which cubes were first hit (so the
/// result is deterministic). Not thread-safe; reuse one instance per thread.
class VoxelGridFilter {
 public:
  /// Keeps one point per cube of edge `voxel_m` (metres, in the input's frame): the point nearest
  /// the cube centre, or the centroid (colour averaged). voxel_m <= 0 copies the input. Points
  /// with non-finite coordinates or beyond +/- 2^20 cubes from the origin are dropped (counted in
  /// droppedLastCall()).
  void apply(const PointCloud& input, double voxel_m, VoxelFilterMode mode, PointCloud& output);

  std::size_t droppedLastCall() const { return dropped_; }

 private:
  struct Cube {
    std::uint32_t best = 0;  ///< index of the kept point (nearest mode)
    float best_d2 = 0.0f;    ///< its squared distance to the cube centre, metres^2
    std::uint32_t count = 0;
    float sum[3] = {0.0f, 0.0f, 0.0f};
    std::uint32_t color_sum[3] = {0, 0, 0};
  };

  std::uint32_t findOrInsert(std::uint64_t key);
  void rehash(std::size_t new_capacity);

  std::vector<std::uint64_t> keys_;   ///< hash table keys; kEmpty = unused
  std::vector<std::uint32_t> slots_;  ///< hash table values: index into cubes_
  std::vector<Cube> cubes_;
  std::size_t dropped_ = 0;
};

}  // namespace slamd
