#include "slamd/synth/sensor_model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "random.hpp"
#include "slamd/common/config.hpp"

namespace slamd::synth {
namespace {

enum NoiseStream : std::uint64_t { kDepthNoise = 0xD3, kColorNoise = 0xC0, kExposure = 0xE7 };

}  // namespace

SensorParams SensorParams::exact() {
  SensorParams p;
  p.depth_noise = false;
  p.depth_quantization = false;
  p.min_range_m = 0.0;
  p.max_range_m = 0.0;
  p.max_incidence_deg = 90.0;
  p.edge_band_px = 0;
  p.color_noise_std = 0.0;
  p.exposure_variation = 0.0;
  p.motion_blur = false;
  return p;
}

SensorParams SensorParams::load(Config& config) {
  const bool exact_mode = config.getBool("synthetic.sensor.exact", false);
  SensorParams p = exact_mode ? exact() : SensorParams();
  p.depth_noise = config.getBool("synthetic.sensor.depth_noise", p.depth_noise);
  p.depth_quantization = config.getBool("synthetic.sensor.depth_quantization", p.depth_quantization);
  p.min_range_m = config.getDouble("synthetic.sensor.min_range_m", p.min_range_m, 0.0, 10.0);
  p.max_range_m = config.getDouble("synthetic.sensor.max_range_m", p.max_range_m, 0.0, 100.0);
  if (p.max_range_m > 0.0 && p.max_range_m <= p.min_range_m) {
    throw ConfigError("synthetic.sensor.max_range_m = " + std::to_string(p.max_range_m) +
                      " must exceed synthetic.sensor.min_range_m = " +
                      std::to_string(p.min_range_m) + " (or be 0 to disable the far gate)");
  }
  p.max_incidence_deg =
      config.getDouble("synthetic.sensor.max_incidence_deg", p.max_incidence_deg, 10.0, 90.0);
  p.edge_band_px = config.getInt("synthetic.sensor.edge_band_px", p.edge_band_px, 0, 10);
  p.edge_jump_fraction =
      config.getDouble("synthetic.sensor.edge_jump_fraction", p.edge_jump_fraction, 0.001, 1.0);
  p.ir_focal_px = config.getDouble("synthetic.sensor.ir_focal_px", p.ir_focal_px, 100.0, 5000.0);
  p.baseline_m = config.getDouble("synthetic.sensor.baseline_m", p.baseline_m, 0.01, 1.0);
  p.disparity_subpixel =
      config.getInt("synthetic.sensor.disparity_subpixel", p.disparity_subpixel, 1, 64);
  p.color_noise_std =
      config.getDouble("synthetic.sensor.color_noise_std", p.color_noise_std, 0.0, 50.0);
  p.exposure_variation =
      config.getDouble("synthetic.sensor.exposure_variation", p.exposure_variation, 0.0, 0.9);
  p.motion_blur = config.getBool("synthetic.sensor.motion_blur", p.motion_blur);
  p.exposure_time_s =
      config.getDouble("synthetic.sensor.exposure_time_s", p.exposure_time_s, 0.0005, 0.1);
  p.blur_samples = config.getInt("synthetic.sensor.blur_samples", p.blur_samples, 2, 32);
  return p;
}

double SensorModel::axialNoiseStdM(double z_m, double incidence_rad) {
  // Nguyen, Izadi & Lovell 2012 (3DIMPVT), fitted axial noise of the Kinect v1.
  const double theta = std::clamp(incidence_rad, 0.0, M_PI / 2.0 - 1e-3);
  const double angular = theta * theta / ((M_PI / 2.0 - theta) * (M_PI / 2.0 - theta));
  return 0.0012 + 0.0019 * (z_m - 0.4) * (z_m - 0.4) + 0.0001 / std::sqrt(z_m) * angular;
}

double SensorModel::quantizeDepth(double z_m) const {
  // Disparity in pixels, rounded to the sensor's sub-pixel step (Khoshelham & Oude Elberink 2012).
  const double fb8 = params_.ir_focal_px * params_.baseline_m * params_.disparity_subpixel;
  const double steps = std::floor(fb8 / z_m + 0.5);
  if (steps < 1.0) return std::numeric_limits<double>::infinity();
  return fb8 / steps;
}

double SensorModel::quantizationStepM(double z_m) const {
  return z_m * z_m / (params_.ir_focal_px * params_.baseline_m * params_.disparity_subpixel);
}

cv::Mat SensorModel::measureDepth(const RenderOutput& render, std::uint64_t seed,
                                  std::int64_t frame) const {
  const cv::Mat& exact = render.depth_m;
  cv::Mat depth = exact.clone();
  const int rows = exact.rows;
  const int cols = exact.cols;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double min_cos = std::cos(params_.max_incidence_deg * M_PI / 180.0);
  const bool gate_incidence = params_.max_incidence_deg < 90.0;
  const int band = params_.edge_band_px;
  // Nearest depth within the edge band around each pixel (a min filter; no return counts as far).
  cv::Mat nearest;
  if (band > 0) {
    cv::Mat finite = exact.clone();
    cv::patchNaNs(finite, std::numeric_limits<float>::max());
    cv::erode(finite, nearest, cv::getStructuringElement(cv::MORPH_RECT,
                                                         cv::Size(2 * band + 1, 2 * band + 1)),
              cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
  }
  Rng rng(deriveSeed(seed, kDepthNoise, static_cast<std::uint64_t>(frame)));
  const float* normal_table = standardNormalTable();
  // Disparity quantisation inline (see quantizeDepth): z = fb8 / round(fb8 / z).
  const double fb8 = params_.ir_focal_px * params_.baseline_m * params_.disparity_subpixel;
  std::uint64_t bits = 0;
  int bits_left = 0;
  for (int r = 0; r < rows; ++r) {
    const float* exact_row = exact.ptr<float>(r);
    const float* cos_row = render.cos_incidence.ptr<float>(r);
    const float* nearest_row = band > 0 ? nearest.ptr<float>(r) : nullptr;
    float* out = depth.ptr<float>(r);
    for (int c = 0; c < cols; ++c) {
      const double z = exact_row[c];
      if (!std::isfinite(z)) continue;
      bool keep = true;
      if (gate_incidence && !(static_cast<double>(cos_row[c]) >= min_cos)) keep = false;
      // A much nearer neighbour: this pixel is on the far side of a depth edge.
      if (band > 0 && static_cast<double>(nearest_row[c]) < z - params_.edge_jump_fraction * z) {
        keep = false;
      }
      if (!keep) {
        out[c] = nan;
        continue;
      }
      double measured = z;
      if (params_.depth_noise) {
        if (bits_left == 0) {
          bits = rng.nextU64();
          bits_left = 4;
        }
        const double n = static_cast<double>(normal_table[bits & 0xFFFF]);
        bits >>= 16;
        --bits_left;
        const double incidence = static_cast<double>(
            std::acos(std::clamp(cos_row[c], 0.0f, 1.0f)));
        measured += axialNoiseStdM(z, incidence) * n;
      }
      if (params_.depth_quantization) {
        // Positive disparities only: +0.5 then truncation is round-half-up.
        const double steps = static_cast<double>(static_cast<std::int64_t>(fb8 / std::max(measured, 1e-3) + 0.5));
        measured = steps >= 1.0 ? fb8 / steps : std::numeric_limits<double>::infinity();
      }
      if ((params_.min_range_m > 0.0 && measured < params_.min_range_m) ||
          (params_.max_range_m > 0.0 && measured > params_.max_range_m) || !(measured > 0.0)) {
        out[c] = nan;
        continue;
      }
      out[c] = static_cast<float>(measured);
    }
  }
  return depth;
}

double SensorModel::exposureGain(std::uint64_t seed, double t_s) const {
  if (params_.exposure_variation <= 0.0) return 1.0;
  // Auto-exposure drifts slowly: a normalised sum of three sinusoids of 0.05..0.3 Hz.
  Rng rng(deriveSeed(seed, kExposure, 0));
  double value = 0.0;
  double total = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double frequency = rng.uniform(0.05, 0.3);
    const double phase = rng.uniform(0.0, 2.0 * M_PI);
    const double weight = rng.uniform(0.5, 1.0);
    value += weight * std::sin(2.0 * M_PI * frequency * t_s + phase);
    total += weight;
  }
  return 1.0 + params_.exposure_variation * value / total;
}

void SensorModel::measureColor(const cv::Mat& color_bgr, std::uint64_t seed, std::int64_t frame,
                               double gain, cv::Mat& color_out) const {
  const bool noisy = params_.color_noise_std > 0.0;
  if (!noisy && gain == 1.0) {
    color_bgr.copyTo(color_out);
    return;
  }
  color_out.create(color_bgr.size(), CV_8UC3);
  Rng rng(deriveSeed(seed, kColorNoise, static_cast<std::uint64_t>(frame)));
  const float sigma = static_cast<float>(params_.color_noise_std);
  const float* normal_table = standardNormalTable();
  const float g = static_cast<float>(gain);
  for (int r = 0; r < color_bgr.rows; ++r) {
    const auto* in = color_bgr.ptr<std::uint8_t>(r);
    auto* out = color_out.ptr<std::uint8_t>(r);
    const int n = color_bgr.cols * 3;
    int k = 0;
    if (noisy) {
      for (; k + 4 <= n; k += 4) {
        std::uint64_t bits = rng.nextU64();
        for (int j = 0; j < 4; ++j) {
          const float noise = sigma * normal_table[bits & 0xFFFF];
          bits >>= 16;
          out[k + j] = cv::saturate_cast<std::uint8_t>(static_cast<float>(in[k + j]) * g + noise);
        }
      }
    }
    for (; k < n; ++k) {
      const float noise = noisy ? sigma * static_cast<float>(rng.normal()) : 0.0f;
      out[k] = cv::saturate_cast<std::uint8_t>(static_cast<float>(in[k]) * g + noise);
    }
  }
}

}  // namespace slamd::synth
