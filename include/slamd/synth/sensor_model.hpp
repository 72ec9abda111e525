#pragma once
// A Kinect v1-like sensor model applied to exact renders (each effect can be switched off).
//
// Usage:
//   SensorModel sensor(SensorParams::load(config));      // or SensorParams::exact()
//   cv::Mat depth_m = sensor.measureDepth(render, seed, frame_index);   // CV_32F, NaN = no data
//   sensor.measureColor(render.color_bgr, seed, frame_index, gain, color_out);
//
// Depth, in this order:
//  1. No return near depth discontinuities: pixels within edge_band_px of a neighbour that is
//     nearer by more than edge_jump_fraction * z (the foreground's shadow and the mixed pixels at
//     edges; Khoshelham & Oude Elberink 2012, Sensors 12(2):1437-1454, sec. 2; Nguyen, Izadi &
//     Lovell 2012, 3DIMPVT, sec. 3).
//  2. No return at grazing incidence beyond max_incidence_deg (the speckle pattern is too
//     stretched to correlate; Nguyen et al. 2012 find the noise diverging as the angle nears 90
//     degrees).
//  3. Axial noise: z + N(0, sigma_z), sigma_z(z, theta) = 0.0012 + 0.0019 (z - 0.4)^2
//     + 0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2 metres (Nguyen et al. 2012, eq. for the
//     axial noise, z in metres, theta the incidence angle in radians): quadratic in depth.
//  4. Quantisation: the Kinect measures disparity d = f_ir * b / z in 1/8-pixel steps (Khoshelham &
//     Oude Elberink 2012: f_ir about 580 px, b about 7.5 cm, 1/8 px disparity resolution, so the
//     depth step grows as z^2 / (8 f_ir b), about 4.6 cm at 4 m).
//  5. Range gate: no depth below min_range_m (about 0.5 m) or beyond max_range_m (about 4.5 m;
//     Khoshelham & Oude Elberink 2012 recommend 1-3 m for mapping, the device reports 0.5-4.5 m).
// Colour: a per-frame exposure gain (auto-exposure changes) and Gaussian noise per channel.
// Motion blur is done by the synthetic source (averaging renders over the exposure time, centred
// on the frame's timestamp).
//
// Noise is drawn from a stream derived from (seed, frame index): the same frame always gets the
// same noise, whatever order frames are rendered in.

#include <cstdint>

#include <opencv2/core.hpp>

#include "slamd/common/config_schema.hpp"
#include "slamd/synth/renderer.hpp"

namespace slamd::synth {

struct SensorParams {
  bool depth_noise = true;
  bool depth_quantization = true;
  double min_range_m = 0.5;          ///< 0 disables the near gate
  double max_range_m = 4.5;          ///< 0 disables the far gate
  double max_incidence_deg = 80.0;   ///< 90 disables the grazing-angle dropout
  int edge_band_px = 1;              ///< 0 disables the dropout at depth edges
  double edge_jump_fraction = 0.04;  ///< depth jump (fraction of z) that makes an edge
  double ir_focal_px = 580.0;        ///< focal length of the IR camera, pixels
  double baseline_m = 0.075;         ///< projector-camera baseline, metres
  int disparity_subpixel = 8;        ///< disparity steps per pixel
  double color_noise_std = 2.0;      ///< grey levels (0..255), 0 disables
  double exposure_variation = 0.0;   ///< peak relative gain change, 0 disables (e.g. 0.15)
  bool motion_blur = false;          ///< average renders over the exposure time
  double exposure_time_s = 0.012;    ///< shutter time for the motion blur, centred on the timestamp
  int blur_samples = 5;     ///< renders averaged per blurred frame (odd: one is the frame's)
  bool exact_mode = false;  ///< made by exact(): the defaults above are all off

  /// Every effect off: depth and colour are the exact render.
  static SensorParams exact();
  /// The `synthetic.sensor.*` keys (rows in sensor_model.cpp).
  static const ConfigSchema<SensorParams>& schema();
  /// Reads "synthetic.sensor.*" (synthetic.sensor.exact: true switches every effect off).
  static SensorParams load(Config& config);
};

class SensorModel {
 public:
  explicit SensorModel(const SensorParams& params) : params_(params) {}

  /// Measured depth (CV_32F metres, NaN = no return) from an exact render.
  cv::Mat measureDepth(const RenderOutput& render, std::uint64_t seed, std::int64_t frame) const;
  /// Measured colour: exact colour times `gain`, plus noise.
  void measureColor(const cv::Mat& color_bgr, std::uint64_t seed, std::int64_t frame, double gain,
                    cv::Mat& color_out) const;
  /// Exposure gain of frame `frame` at time t_s (1 when exposure changes are off).
  double exposureGain(std::uint64_t seed, double t_s) const;

  /// Axial noise standard deviation (metres) at depth z_m and incidence angle (radians).
  static double axialNoiseStdM(double z_m, double incidence_rad);
  /// Depth after disparity quantisation with this model's camera.
  double quantizeDepth(double z_m) const;
  /// Depth step between neighbouring disparity levels at z_m (metres).
  double quantizationStepM(double z_m) const;

  const SensorParams& params() const { return params_; }

 private:
  SensorParams params_;
};

}  // namespace slamd::synth
