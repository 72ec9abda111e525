#include "slamd/capture/depth_preprocessor.hpp"

#include <cmath>
#include <limits>
#include <vector>

#include "slamd/common/time.hpp"

namespace slamd {

DepthPreprocessorConfig DepthPreprocessorConfig::load(Config& config) {
  DepthPreprocessorConfig out;
  out.range_gate = config.getBool("capture.preprocess.range_gate", out.range_gate);
  out.min_depth_m = config.getDouble("capture.preprocess.min_depth_m", out.min_depth_m, 0.0, 100.0);
  out.max_depth_m = config.getDouble("capture.preprocess.max_depth_m", out.max_depth_m, 0.0, 100.0);
  if (out.max_depth_m <= out.min_depth_m) {
    throw ConfigError("capture.preprocess.max_depth_m=" + std::to_string(out.max_depth_m) +
                      " must be greater than capture.preprocess.min_depth_m=" +
                      std::to_string(out.min_depth_m));
  }
  out.flying_pixels = config.getBool("capture.preprocess.flying_pixels", out.flying_pixels);
  out.jump_ratio =
      config.getDouble("capture.preprocess.flying_jump_ratio", out.jump_ratio, 1e-4, 1.0);
  out.min_support = config.getInt("capture.preprocess.flying_min_support", out.min_support, 0, 8);
  out.bilateral = config.getBool("capture.preprocess.bilateral", out.bilateral);
  out.bilateral_radius_px =
      config.getInt("capture.preprocess.bilateral_radius_px", out.bilateral_radius_px, 1, 7);
  out.spatial_sigma_px = config.getDouble("capture.preprocess.bilateral_spatial_sigma_px",
                                          out.spatial_sigma_px, 1e-3, 20.0);
  out.range_sigma_ratio = config.getDouble("capture.preprocess.bilateral_range_sigma_ratio",
                                           out.range_sigma_ratio, 1e-4, 1.0);
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
  // Decisions are made on an unmodified copy so that removals do not cascade.
  depth_m.copyTo(scratch_);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const auto ratio = static_cast<float>(config_.jump_ratio);
  const int rows = depth_m.rows;
  const int cols = depth_m.cols;
  int removed = 0;
  for (int r = 0; r < rows; ++r) {
    const float* above = scratch_.ptr<float>(r > 0 ? r - 1 : r);
    const float* here = scratch_.ptr<float>(r);
    const float* below = scratch_.ptr<float>(r + 1 < rows ? r + 1 : r);
    auto* out = depth_m.ptr<float>(r);
    for (int c = 0; c < cols; ++c) {
      const float z = here[c];
      if (!(z > 0.0f)) continue;  // NaN or non-positive
      const float jump = ratio * z;
      bool nearer = false;
      bool farther = false;
      int support = 0;
      int neighbours = 0;
      const int c0 = c > 0 ? c - 1 : c;
      const int c1 = c + 1 < cols ? c + 1 : c;
      const float* lines[3] = {r > 0 ? above : nullptr, here, r + 1 < rows ? below : nullptr};
      for (const float* line : lines) {
        if (line == nullptr) continue;
        for (int k = c0; k <= c1; ++k) {
          if (line == here && k == c) continue;
          const float zn = line[k];
          if (!(zn > 0.0f)) continue;
          ++neighbours;
          const float d = zn - z;
          if (d > jump) {
            farther = true;
          } else if (d < -jump) {
            nearer = true;
          } else {
            ++support;
          }
        }
      }
      if ((nearer && farther) || (neighbours > 0 && support < config_.min_support) ||
          (neighbours == 0 && config_.min_support > 0)) {
        out[c] = nan;
        ++removed;
      }
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
  const auto ratio = static_cast<float>(config_.range_sigma_ratio);
  const int rows = depth_m.rows;
  const int cols = depth_m.cols;
  for (int r = 0; r < rows; ++r) {
    auto* out = depth_m.ptr<float>(r);
    const float* centre_row = scratch_.ptr<float>(r);
    for (int c = 0; c < cols; ++c) {
      const float z = centre_row[c];
      if (!(z > 0.0f)) continue;
      const float sigma = ratio * z;
      const float inv_two_sigma2 = 1.0f / (2.0f * sigma * sigma);
      // Neighbours beyond 3 sigma contribute < 1.2% weight: skip them (and the exp) outright.
      const float cutoff = 3.0f * sigma;
      float weight_sum = 0.0f;
      float value_sum = 0.0f;
      const int r0 = r - radius < 0 ? 0 : r - radius;
      const int r1 = r + radius >= rows ? rows - 1 : r + radius;
      const int c0 = c - radius < 0 ? 0 : c - radius;
      const int c1 = c + radius >= cols ? cols - 1 : c + radius;
      for (int rr = r0; rr <= r1; ++rr) {
        const float* line = scratch_.ptr<float>(rr);
        const float* weights = &spatial[static_cast<std::size_t>((rr - r + radius) * size)];
        for (int cc = c0; cc <= c1; ++cc) {
          const float zn = line[cc];
          const float d = zn - z;
          if (!(std::abs(d) < cutoff)) continue;  // also skips NaN
          const float w = weights[cc - c + radius] * std::exp(-d * d * inv_two_sigma2);
          weight_sum += w;
          value_sum += w * zn;
        }
      }
      out[c] = value_sum / weight_sum;  // the centre always contributes (weight 1)
    }
  }
}

}  // namespace slamd
