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
  p.exact_mode = true;
  return p;
}

const ConfigSchema<SensorParams>& SensorParams::schema() {
  using C = SensorParams;
  static const auto table =
      ConfigSchema<C>("synthetic.sensor")
          .flag("exact", &C::exact_mode,
                "switch every effect off (depth and colour are the exact render); the keys below "
                "then default to off")
          .flag("depth_noise", &C::depth_noise, "Kinect v1 axial depth noise")
          .flag("depth_quantization", &C::depth_quantization, "disparity quantisation of depth")
          .number("min_range_m", &C::min_range_m, 0.0, 10.0, "m",
                  "nearer depth is dropped; 0 disables the near gate")
          .number("max_range_m", &C::max_range_m, 0.0, 100.0, "m",
                  "farther depth is dropped; > min_range_m, or 0 to disable the far gate")
          .number("max_incidence_deg", &C::max_incidence_deg, 10.0, 90.0, "deg",
                  "depth at more grazing angles drops out; 90 disables")
          .number("edge_band_px", &C::edge_band_px, 0, 10, "px",
                  "dropout band at depth edges; 0 disables")
          .number("edge_jump_fraction", &C::edge_jump_fraction, 0.001, 1.0, "",
                  "depth jump (fraction of z) that makes an edge")
          .number("ir_focal_px", &C::ir_focal_px, 100.0, 5000.0, "px",
                  "focal length of the IR camera")
          .number("baseline_m", &C::baseline_m, 0.01, 1.0, "m", "projector-camera baseline")
          .number("disparity_subpixel", &C::disparity_subpixel, 1, 64, "",
                  "disparity steps per pixel")
          .number("color_noise_std", &C::color_noise_std, 0.0, 50.0, "grey levels",
                  "colour noise; 0 disables")
          .number("exposure_variation", &C::exposure_variation, 0.0, 0.9, "",
                  "peak relative gain change; 0 disables")
          .flag("motion_blur", &C::motion_blur, "average renders over the exposure time")
          .number("exposure_time_s", &C::exposure_time_s, 0.0005, 0.1, "s",
                  "shutter time of the motion blur, centred on the timestamp")
          .number("blur_samples", &C::blur_samples, 2, 32, "",
                  "renders averaged per blurred frame (odd: one is the frame's)");
  return table;
}

SensorParams SensorParams::load(Config& config) {
  SensorParams p;
  schema().load(config, p);
  if (p.exact_mode) {  // read again over the exact defaults
    p = exact();
    schema().load(config, p);
  }
  if (p.max_range_m > 0.0 && p.max_range_m <= p.min_range_m) {
    throw ConfigError("synthetic.sensor.max_range_m = " + std::to_string(p.max_range_m) +
                      " must exceed synthetic.sensor.min_range_m = " +
                      std::to_string(p.min_range_m) + " (or be 0 to disable the far gate)");
  }
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
    cv::erode(finite, nearest,
              cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * band + 1, 2 * band + 1)),
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
        const double incidence = static_cast<double>(std::acos(std::clamp(cos_row[c], 0.0f, 1.0f)));
        measured += axialNoiseStdM(z, incidence) * n;
      }
      if (params_.depth_quantization) {
        // Positive disparities only: +0.5 then truncation is round-half-up.
        const double steps =
            static_cast<double>(static_cast<std::int64_t>(fb8 / std::max(measured, 1e-3) + 0.5));
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
