#include "slamd/capture/depth_preprocessor.hpp"

#include <cmath>
#include <limits>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/common/time.hpp"

namespace slamd {

const ConfigSchema<DepthPreprocessorConfig>& DepthPreprocessorConfig::schema() {
  using C = DepthPreprocessorConfig;
  static const auto table =
      ConfigSchema<C>("capture.preprocess")
          .flag("range_gate", &C::range_gate, "drop depth outside [min_depth_m, max_depth_m]")
          .number("min_depth_m", &C::min_depth_m, 0.0, 100.0, "m", "nearest depth kept")
          .number("max_depth_m", &C::max_depth_m, 0.0, 100.0, "m",
                  "farthest depth kept; > min_depth_m")
          .flag("flying_pixels", &C::flying_pixels,
                "remove pixels floating between a foreground edge and the background, and "
                "isolated speckle")
          .number("flying_jump_ratio", &C::jump_ratio, 1e-4, 1.0, "",
                  "a neighbour differing by more than this fraction of the depth is a jump")
          .number("flying_min_support", &C::min_support, 0, 8, "neighbours",
                  "a pixel with fewer of its 8 neighbours within the jump is speckle")
          .flag("bilateral", &C::bilateral, "edge-preserving bilateral smoothing of the depth")
          .number("bilateral_radius_px", &C::bilateral_radius_px, 1, 7, "px",
                  "bilateral filter radius")
          .number("bilateral_spatial_sigma_px", &C::spatial_sigma_px, 1e-3, 20.0, "px",
                  "bilateral spatial sigma")
          .number("bilateral_range_sigma_ratio", &C::range_sigma_ratio, 1e-4, 1.0, "",
                  "bilateral range sigma as a fraction of the depth (noise grows with depth)");
  return table;
}

DepthPreprocessorConfig DepthPreprocessorConfig::load(Config& config) {
  DepthPreprocessorConfig out;
  schema().load(config, out);
  if (out.max_depth_m <= out.min_depth_m) {
    throw ConfigError(
        "capture.preprocess.max_depth_m=" + std::to_string(out.max_depth_m) +
        " must be greater than capture.preprocess.min_depth_m=" + std::to_string(out.min_depth_m));
  }
  return out;
}

DepthPreprocessor::DepthPreprocessor(DepthPreprocessorConfig config) : config_(config) {}

DepthPreprocessTimings DepthPreprocessor::process(cv::Mat& depth_m) {
  CV_Assert(depth_m.type() == CV_32FC1);
  DepthPreprocessTimings timings;
  if (config_.range_gate) {
    const std::int64_t start = steadyNowNs();
    rangeGate(depth_m);
    timings.range_gate_ns = steadyNowNs() - start;
  }
  if (config_.flying_pixels) {
    const std::int64_t start = steadyNowNs();
    removeFlyingPixels(depth_m);
    timings.flying_pixels_ns = steadyNowNs() - start;
  }
  if (config_.bilateral) {
    const std::int64_t start = steadyNowNs();
    bilateral(depth_m);
    timings.bilateral_ns = steadyNowNs() - start;
  }
  return timings;
}

int DepthPreprocessor::rangeGate(cv::Mat& depth_m) const {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const auto min_m = static_cast<float>(config_.min_depth_m);
  const auto max_m = static_cast<float>(config_.max_depth_m);
  int removed = 0;
  for (int r = 0; r < depth_m.rows; ++r) {
    auto* row = depth_m.ptr<float>(r);
    for (int c = 0; c < depth_m.cols; ++c) {
      const float z = row[c];
      // NaN compares false, so it stays NaN without being counted.
      if (z < min_m || z > max_m) {
        row[c] = nan;
        ++removed;
      }
    }
  }
  return removed;
}

int DepthPreprocessor::removeFlyingPixels(cv::Mat& depth_m) {
  // Decisions are made on a copy padded with one NaN pixel on each side, so that removals do not
  // cascade and the border needs no special case (NaN neighbours are ignored).
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::copyMakeBorder(depth_m, scratch_, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(nan));
  const float ratio = static_cast<float>(config_.jump_ratio);
  const int min_support = config_.min_support;
  const int rows = depth_m.rows;
  const int cols = depth_m.cols;
  int removed = 0;
  for (int r = 0; r < rows; ++r) {
    const float* above = scratch_.ptr<float>(r) + 1;
    const float* here = scratch_.ptr<float>(r + 1) + 1;
    const float* below = scratch_.ptr<float>(r + 2) + 1;
    auto* out = depth_m.ptr<float>(r);
    // Branch-free so that the compiler vectorises it: comparisons with NaN are false, so missing
    // neighbours (and a missing centre) count nowhere.
    for (int c = 0; c < cols; ++c) {
      const float z = here[c];
      const float jump = ratio * z;
      const float neighbours[8] = {above[c - 1], above[c],     above[c + 1], here[c - 1],
                                   here[c + 1],  below[c - 1], below[c],     below[c + 1]};
      bool nearer = false;
      bool farther = false;
      int support = 0;
      for (const float zn : neighbours) {
        const float d = zn - z;
        farther |= d > jump;
        nearer |= d < -jump;
        support += (d <= jump) & (d >= -jump);
      }
      const bool remove = (z > 0.0f) & ((nearer & farther) | (support < min_support));
      removed += remove;
      out[c] = remove ? nan : out[c];
    }
  }
  return removed;
}

void DepthPreprocessor::bilateral(cv::Mat& depth_m) {
  depth_m.copyTo(scratch_);
  const int radius = config_.bilateral_radius_px;
  const int size = 2 * radius + 1;
  std::vector<float> spatial(static_cast<std::size_t>(size * size));
  const double two_sigma2 = 2.0 * config_.spatial_sigma_px * config_.spatial_sigma_px;
  for (int dy = -radius; dy <= radius; ++dy) {
    for (int dx = -radius; dx <= radius; ++dx) {
      spatial[static_cast<std::size_t>((dy + radius) * size + dx + radius)] =
          static_cast<float>(std::exp(-(dx * dx + dy * dy) / two_sigma2));
    }
  }
  // Range weight exp(-u^2 / 2) tabulated over u = |d| / sigma in [0, 3); neighbours beyond 3 sigma
  // (weight < 1.2%) are left out. The table step (3/256 sigma) is far below depth noise.
  constexpr int kTable = 256;
  constexpr float kMaxU = 3.0f;
  float range_table[kTable];
  for (int i = 0; i < kTable; ++i) {
    const double u = (i + 0.5) * static_cast<double>(kMaxU) / kTable;
    range_table[i] = static_cast<float>(std::exp(-0.5 * u * u));
  }
  const auto ratio = static_cast<float>(config_.range_sigma_ratio);
  const int rows = depth_m.rows;
  const int cols = depth_m.cols;
  for (int r = 0; r < rows; ++r) {
    auto* out = depth_m.ptr<float>(r);
    const float* centre_row = scratch_.ptr<float>(r);
    const int r0 = r - radius < 0 ? 0 : r - radius;
    const int r1 = r + radius >= rows ? rows - 1 : r + radius;
    for (int c = 0; c < cols; ++c) {
      const float z = centre_row[c];
      if (!(z > 0.0f)) continue;
      const float to_index = kTable / (kMaxU * ratio * z);  // |d| -> table index
      float weight_sum = 0.0f;
      float value_sum = 0.0f;
      const int c0 = c - radius < 0 ? 0 : c - radius;
      const int c1 = c + radius >= cols ? cols - 1 : c + radius;
      for (int rr = r0; rr <= r1; ++rr) {
        const float* line = scratch_.ptr<float>(rr);
        const float* weights = &spatial[static_cast<std::size_t>((rr - r + radius) * size)];
        for (int cc = c0; cc <= c1; ++cc) {
          const float zn = line[cc];
          const float index = std::abs(zn - z) * to_index;
          if (!(index < static_cast<float>(kTable))) continue;  // beyond 3 sigma, or NaN
          const float w = weights[cc - c + radius] * range_table[static_cast<int>(index)];
          weight_sum += w;
          value_sum += w * zn;
        }
      }
      out[c] = value_sum / weight_sum;  // the centre always contributes
    }
  }
}

}  // namespace slamd
