#include "slamd/mapping/point_cloud.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace slamd {

const char* toString(DepthCloudStatus status) {
  switch (status) {
    case DepthCloudStatus::kOk:
      return "ok";
    case DepthCloudStatus::kBadDepthType:
      return "depth image is not CV_32FC1";
    case DepthCloudStatus::kSizeMismatch:
      return "depth image size differs from the intrinsics";
    case DepthCloudStatus::kBadIntrinsics:
      return "invalid intrinsics";
    case DepthCloudStatus::kBadOptions:
      return "invalid depth-to-cloud options";
  }
  return "unknown";
}

DepthCloudStatus depthToCloud(const cv::Mat& depth_m, const cv::Mat& color_bgr,
                              const CameraIntrinsics& intrinsics,
                              const DepthToCloudOptions& options, PointCloud& cloud,
                              DepthCloudStats& stats) {
  cloud.clear();
  stats = DepthCloudStats{};
  if (depth_m.empty() || depth_m.type() != CV_32FC1) return DepthCloudStatus::kBadDepthType;
  if (depth_m.cols != intrinsics.width || depth_m.rows != intrinsics.height) {
    return DepthCloudStatus::kSizeMismatch;
  }
  const bool intrinsics_ok = std::isfinite(intrinsics.fx) && std::isfinite(intrinsics.fy) &&
                             std::isfinite(intrinsics.cx) && std::isfinite(intrinsics.cy) &&
                             intrinsics.fx > 0.0 && intrinsics.fy > 0.0;
  if (!intrinsics_ok) return DepthCloudStatus::kBadIntrinsics;
  if (options.pixel_stride < 1 || !std::isfinite(options.min_depth_m) ||
      !std::isfinite(options.max_depth_m) || options.min_depth_m > options.max_depth_m) {
    return DepthCloudStatus::kBadOptions;
  }
  const bool with_color =
      !color_bgr.empty() && color_bgr.type() == CV_8UC3 && color_bgr.size() == depth_m.size();
  stats.color_used = with_color;

  const int stride = options.pixel_stride;
  const float min_z = static_cast<float>(options.min_depth_m);
  const float max_z = static_cast<float>(options.max_depth_m);
  // Per-column and per-row ray slopes, computed once per frame.
  std::vector<float> x_slope;
  for (int u = 0; u < depth_m.cols; u += stride) {
    x_slope.push_back(static_cast<float>((u - intrinsics.cx) / intrinsics.fx));
  }
  const std::size_t expected =
      x_slope.size() * static_cast<std::size_t>((depth_m.rows + stride - 1) / stride);
  cloud.points.reserve(expected);
  if (with_color) cloud.colors_bgr.reserve(expected);

  for (int v = 0; v < depth_m.rows; v += stride) {
    const float y_slope = static_cast<float>((v - intrinsics.cy) / intrinsics.fy);
    const float* row = depth_m.ptr<float>(v);
    const cv::Vec3b* color_row = with_color ? color_bgr.ptr<cv::Vec3b>(v) : nullptr;
    for (std::size_t i = 0; i < x_slope.size(); ++i) {
      const int u = static_cast<int>(i) * stride;
      const float z = row[u];
      ++stats.sampled;
      // One comparison accepts the common case; the rest only classifies rejects.
      if (z >= min_z && z <= max_z && z > 0.0f) {
        cloud.points.emplace_back(x_slope[i] * z, y_slope * z, z);
        if (with_color) {
          const cv::Vec3b& c = color_row[u];
          cloud.colors_bgr.push_back({c[0], c[1], c[2]});
        }
        continue;
      }
      if (std::isnan(z)) {
        ++stats.nan;
      } else if (std::isinf(z)) {
        ++stats.infinite;
      } else if (z == 0.0f) {
        ++stats.zero;
      } else if (z < 0.0f) {
        ++stats.negative;
      } else if (z < min_z) {
        ++stats.too_near;
      } else {
        ++stats.too_far;
      }
    }
  }
  stats.valid = static_cast<std::int64_t>(cloud.points.size());
  return DepthCloudStatus::kOk;
}

namespace {

constexpr std::uint64_t kEmpty = std::numeric_limits<std::uint64_t>::max();
constexpr std::int64_t kCubeOffset = std::int64_t{1} << 20;  // 21 bits per axis

inline std::size_t hashKey(std::uint64_t key, std::size_t mask) {
  // Fibonacci hashing: multiply by 2^64 / golden ratio, keep the high bits.
  return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> 32) & mask;
}

/// floor() for values known to fit: truncation, then one step down for negative fractions
/// (std::floor is a library call on baseline x86-64 and dominated the filter's time).
inline std::int64_t floorToInt(double value) {
  const auto truncated = static_cast<std::int64_t>(value);
  return static_cast<double>(truncated) > value ? truncated - 1 : truncated;
}

}  // namespace

void VoxelGridFilter::rehash(std::size_t new_capacity) {
  std::vector<std::uint64_t> old_keys(new_capacity, kEmpty);
  std::vector<std::uint32_t> old_slots(new_capacity, 0);
  old_keys.swap(keys_);
  old_slots.swap(slots_);
  const std::size_t mask = new_capacity - 1;
  for (std::size_t i = 0; i < old_keys.size(); ++i) {
    if (old_keys[i] == kEmpty) continue;
    std::size_t h = hashKey(old_keys[i], mask);
    while (keys_[h] != kEmpty) h = (h + 1) & mask;
    keys_[h] = old_keys[i];
    slots_[h] = old_slots[i];
  }
}

std::uint32_t VoxelGridFilter::findOrInsert(std::uint64_t key) {
  // Keep the load factor below 1/2 so linear probes stay short.
  if (2 * (cubes_.size() + 1) > keys_.size()) rehash(keys_.size() * 2);
  const std::size_t mask = keys_.size() - 1;
  std::size_t h = hashKey(key, mask);
  while (true) {
    if (keys_[h] == key) return slots_[h];
    if (keys_[h] == kEmpty) {
      keys_[h] = key;
      slots_[h] = static_cast<std::uint32_t>(cubes_.size());
      cubes_.emplace_back();
      return slots_[h];
    }
    h = (h + 1) & mask;
  }
}

void VoxelGridFilter::apply(const PointCloud& input, double voxel_m, VoxelFilterMode mode,
                            PointCloud& output) {
  output.clear();
  dropped_ = 0;
  const bool with_color = input.hasColor() && input.colors_bgr.size() == input.points.size();
  if (!(voxel_m > 0.0) || !std::isfinite(voxel_m)) {
    for (std::size_t i = 0; i < input.points.size(); ++i) {
      if (!input.points[i].allFinite()) {
        ++dropped_;
        continue;
      }
      output.points.push_back(input.points[i]);
      if (with_color) output.colors_bgr.push_back(input.colors_bgr[i]);
    }
    return;
  }
  // Start from a table sized for the last frame's cube count (frames are alike).
  const std::size_t wanted = std::max<std::size_t>(1024, 4 * cubes_.size());
  std::size_t capacity = 1024;
  while (capacity < wanted) capacity *= 2;
  if (keys_.size() != capacity) {
    keys_.assign(capacity, kEmpty);
    slots_.assign(capacity, 0);
  } else {
    std::fill(keys_.begin(), keys_.end(), kEmpty);
  }
  cubes_.clear();

  const double inv = 1.0 / voxel_m;
  const float voxel_f = static_cast<float>(voxel_m);
  const double limit = static_cast<double>(kCubeOffset - 1);
  std::uint64_t last_key = kEmpty;
  std::uint32_t last_cube = 0;
  for (std::size_t i = 0; i < input.points.size(); ++i) {
    const Eigen::Vector3f& p = input.points[i];
    const double gx = static_cast<double>(p.x()) * inv;
    const double gy = static_cast<double>(p.y()) * inv;
    const double gz = static_cast<double>(p.z()) * inv;
    // NaN fails every comparison, so non-finite points are dropped here too.
    if (!(std::abs(gx) < limit && std::abs(gy) < limit && std::abs(gz) < limit)) {
      ++dropped_;
      continue;
    }
    const std::int64_t ix = floorToInt(gx);
    const std::int64_t iy = floorToInt(gy);
    const std::int64_t iz = floorToInt(gz);
    const std::uint64_t key = static_cast<std::uint64_t>(ix + kCubeOffset) |
                              (static_cast<std::uint64_t>(iy + kCubeOffset) << 21) |
                              (static_cast<std::uint64_t>(iz + kCubeOffset) << 42);
    // Neighbouring pixels mostly fall into the same cube: skip the hash lookup for them.
    if (key != last_key) {
      last_key = key;
      last_cube = findOrInsert(key);
    }
    Cube& cube = cubes_[last_cube];
    if (mode == VoxelFilterMode::kNearestToCentre) {
      const float dx = p.x() - (static_cast<float>(ix) + 0.5f) * voxel_f;
      const float dy = p.y() - (static_cast<float>(iy) + 0.5f) * voxel_f;
      const float dz = p.z() - (static_cast<float>(iz) + 0.5f) * voxel_f;
      const float d2 = dx * dx + dy * dy + dz * dz;
      if (cube.count == 0 || d2 < cube.best_d2) {
        cube.best = static_cast<std::uint32_t>(i);
        cube.best_d2 = d2;
      }
    } else {
      for (int k = 0; k < 3; ++k) cube.sum[k] += p[k];
      if (with_color) {
        for (int k = 0; k < 3; ++k) cube.color_sum[k] += input.colors_bgr[i][k];
      }
    }
    ++cube.count;
  }

  output.points.reserve(cubes_.size());
  if (with_color) output.colors_bgr.reserve(cubes_.size());
  for (const Cube& cube : cubes_) {
    if (mode == VoxelFilterMode::kNearestToCentre) {
      output.points.push_back(input.points[cube.best]);
      if (with_color) output.colors_bgr.push_back(input.colors_bgr[cube.best]);
    } else {
      const float n = static_cast<float>(cube.count);
      output.points.emplace_back(cube.sum[0] / n, cube.sum[1] / n, cube.sum[2] / n);
      if (with_color) {
        ColorBgr c{};
        for (int k = 0; k < 3; ++k) {
          c[static_cast<std::size_t>(k)] =
              static_cast<std::uint8_t>((cube.color_sum[k] + cube.count / 2) / cube.count);
        }
        output.colors_bgr.push_back(c);
      }
    }
  }
}

}  // namespace slamd
