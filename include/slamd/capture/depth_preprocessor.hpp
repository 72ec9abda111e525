#pragma once
// DepthPreprocessor: the depth clean-up steps of the 3D-modelling thesis, each optional and timed.
//
//   DepthPreprocessor pre(DepthPreprocessorConfig::load(config));   // capture.preprocess.*
//   DepthPreprocessTimings t = pre.process(depth_m);                // in place
//
// Input and output: CV_32FC1 depth in metres along the optical axis, NaN = no measurement.
// Steps, in order:
//  1. Range gate: depth outside [min_depth_m, max_depth_m] becomes NaN.
//  2. Flying-pixel removal: a pixel is removed (NaN) when, among its 8 neighbours, one is nearer
//     and one is farther by more than jump_ratio * depth (it floats between a foreground edge and
//     the background), or when fewer than min_support neighbours lie within that jump (isolated
//     speckle). True object edges keep their pixels.
//  3. Edge-preserving smoothing: a bilateral filter over a (2r+1)^2 window that ignores NaN
//     neighbours; the range weight uses sigma = range_sigma_ratio * depth (sensor noise grows with
//     depth), so depth steps larger than a few sigma are not blurred across. NaN stays NaN.
// Flying pixels are removed before smoothing so that they cannot pull edge pixels.
//
// No threads inside; not thread-safe (one per capture thread). process() allocates one scratch
// image per call for the filters that need a copy.

#include <cstdint>

#include <opencv2/core.hpp>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

/// Keys `capture.preprocess.*` (type, default, range, unit and doc of each: its row in
/// depth_preprocessor.cpp, or `slamd --describe-config capture`).
struct DepthPreprocessorConfig {
  bool range_gate = true;
  double min_depth_m = 0.3;
  double max_depth_m = 8.0;
  bool flying_pixels = true;
  double jump_ratio = 0.05;
  int min_support = 2;
  bool bilateral = false;
  int bilateral_radius_px = 2;
  double spatial_sigma_px = 1.5;
  double range_sigma_ratio = 0.01;

  static const ConfigSchema<DepthPreprocessorConfig>& schema();
  static DepthPreprocessorConfig load(Config& config);
  bool anyEnabled() const { return range_gate || flying_pixels || bilateral; }
};

/// Time spent in each step of one process() call (0 for disabled steps).
struct DepthPreprocessTimings {
  std::int64_t range_gate_ns = 0;
  std::int64_t flying_pixels_ns = 0;
  std::int64_t bilateral_ns = 0;
  std::int64_t totalNs() const { return range_gate_ns + flying_pixels_ns + bilateral_ns; }
};

class DepthPreprocessor {
 public:
  explicit DepthPreprocessor(DepthPreprocessorConfig config);

  /// Cleans `depth_m` (CV_32FC1 metres) in place.
  DepthPreprocessTimings process(cv::Mat& depth_m);

  /// The individual steps, for tests and benchmarks. Return the number of pixels set to NaN.
  int rangeGate(cv::Mat& depth_m) const;
  int removeFlyingPixels(cv::Mat& depth_m);
  void bilateral(cv::Mat& depth_m);

  const DepthPreprocessorConfig& config() const { return config_; }

 private:
  DepthPreprocessorConfig config_;
  cv::Mat scratch_;
};

}  // namespace slamd
