#include "slamd/synth/sensor_model.hpp"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace slamd::synth {
namespace {

/// A fronto-parallel plane at depth_m filling a 640x480 render.
RenderOutput flatRender(double depth_m, double cos_incidence = 1.0) {
  RenderOutput out;
  out.depth_m = cv::Mat(480, 640, CV_32FC1, cv::Scalar(depth_m));
  out.cos_incidence = cv::Mat(480, 640, CV_32FC1, cv::Scalar(cos_incidence));
  out.surface_id = cv::Mat(480, 640, CV_32SC1, cv::Scalar(0));
  out.color_bgr = cv::Mat(480, 640, CV_8UC3, cv::Scalar(100, 120, 140));
  return out;
}

struct ErrorStats {
  double mean = 0.0;
  double stddev = 0.0;
  int valid = 0;
};

ErrorStats depthErrorStats(const cv::Mat& measured, double truth) {
  ErrorStats stats;
  double sum = 0.0;
  double sum_sq = 0.0;
  for (int r = 0; r < measured.rows; ++r) {
    for (int c = 0; c < measured.cols; ++c) {
      const double z = measured.at<float>(r, c);
      if (!std::isfinite(z)) continue;
      sum += z - truth;
      sum_sq += (z - truth) * (z - truth);
      ++stats.valid;
    }
  }
  stats.mean = sum / stats.valid;
  stats.stddev = std::sqrt(sum_sq / stats.valid - stats.mean * stats.mean);
  return stats;
}

SensorParams noiseOnly() {
  SensorParams params = SensorParams::exact();
  params.depth_noise = true;
  return params;
}

TEST(SensorModel, DepthNoiseMatchesTheAxialModelAtOneAndThreeMetres) {
  const SensorModel sensor(noiseOnly());
  for (double z : {1.0, 3.0}) {
    const ErrorStats stats = depthErrorStats(sensor.measureDepth(flatRender(z), 7, 0), z);
    const double sigma = SensorModel::axialNoiseStdM(z, 0.0);
    ASSERT_EQ(stats.valid, 640 * 480);
    // 307200 samples: the mean's standard error is sigma / 554; the spread's is about 0.13 %.
    EXPECT_LT(std::abs(stats.mean), 5.0 * sigma / std::sqrt(stats.valid)) << "z " << z;
    EXPECT_NEAR(stats.stddev / sigma, 1.0, 0.01) << "z " << z;
  }
  // Quadratic growth: Nguyen et al.'s sigma is 2.9 mm at 1 m and 16.1 mm at 3 m.
  EXPECT_NEAR(SensorModel::axialNoiseStdM(1.0, 0.0), 0.0012 + 0.0019 * 0.36, 1e-12);
  EXPECT_NEAR(SensorModel::axialNoiseStdM(3.0, 0.0), 0.0012 + 0.0019 * 6.76, 1e-12);
}

TEST(SensorModel, NoiseWithQuantisationHasTheModelsMeanAndSpread) {
  const SensorModel sensor{SensorParams()};
  for (double z : {1.0, 3.0}) {
    const ErrorStats stats = depthErrorStats(sensor.measureDepth(flatRender(z), 11, 3), z);
    const double sigma = SensorModel::axialNoiseStdM(z, 0.0);
    const double step = sensor.quantizationStepM(z);
    // Independent noise and uniform rounding error: variances add (step^2 / 12).
    const double expected = std::sqrt(sigma * sigma + step * step / 12.0);
    EXPECT_NEAR(stats.stddev / expected, 1.0, 0.05) << "z " << z;
    EXPECT_LT(std::abs(stats.mean), 0.1 * expected) << "z " << z;
  }
}

TEST(SensorModel, QuantisedDepthsLieOnEighthPixelDisparitySteps) {
  SensorParams params = SensorParams::exact();
  params.depth_quantization = true;
  const SensorModel sensor(params);
  const double fb = params.ir_focal_px * params.baseline_m;
  for (double z : {0.8, 1.7, 2.9, 4.2}) {
    const double measured = sensor.measureDepth(flatRender(z), 1, 0).at<float>(100, 100);
    const double eighths = fb / measured * 8.0;
    EXPECT_NEAR(eighths, std::round(eighths), 1e-3) << "z " << z;
    EXPECT_LE(std::abs(measured - z), 0.51 * sensor.quantizationStepM(z)) << "z " << z;
  }
  // Khoshelham & Oude Elberink: about 4.6 cm between levels at 4 m with f = 580 px, b = 7.5 cm.
  EXPECT_NEAR(sensor.quantizationStepM(4.0), 0.046, 0.001);
}

TEST(SensorModel, NoDepthOutsideTheRangeOrAtGrazingAngles) {
  const SensorModel sensor{SensorParams()};
  const auto valid = [&](const RenderOutput& render) {
    const cv::Mat depth = sensor.measureDepth(render, 3, 0);
    return cv::countNonZero(depth == depth);
  };
  EXPECT_EQ(valid(flatRender(0.4)), 0);
  EXPECT_EQ(valid(flatRender(5.0)), 0);
  EXPECT_EQ(valid(flatRender(2.0, std::cos(85.0 * M_PI / 180.0))), 0);
  EXPECT_EQ(valid(flatRender(2.0, std::cos(60.0 * M_PI / 180.0))), 640 * 480);
}

TEST(SensorModel, DropsTheFarSideOfDepthEdges) {
  SensorParams params = SensorParams::exact();
  params.edge_band_px = 2;
  const SensorModel sensor(params);
  RenderOutput render = flatRender(3.0);
  render.depth_m(cv::Rect(0, 0, 320, 480)).setTo(cv::Scalar(1.0));  // foreground on the left
  const cv::Mat depth = sensor.measureDepth(render, 1, 0);
  EXPECT_FLOAT_EQ(depth.at<float>(240, 319), 1.0f);  // near side kept
  EXPECT_TRUE(std::isnan(depth.at<float>(240, 320)));
  EXPECT_TRUE(std::isnan(depth.at<float>(240, 321)));
  EXPECT_FLOAT_EQ(depth.at<float>(240, 322), 3.0f);
}

TEST(SensorModel, ExactModeChangesNothing) {
  const SensorModel sensor(SensorParams::exact());
  RenderOutput render = flatRender(7.5);
  render.depth_m.at<float>(5, 5) = std::numeric_limits<float>::quiet_NaN();
  cv::Mat depth = sensor.measureDepth(render, 1, 0);
  EXPECT_TRUE(std::isnan(depth.at<float>(5, 5)));
  cv::Mat expected = render.depth_m.clone();
  cv::patchNaNs(depth, -1.0);
  cv::patchNaNs(expected, -1.0);
  EXPECT_EQ(cv::norm(depth, expected, cv::NORM_INF), 0.0);
  cv::Mat color;
  sensor.measureColor(render.color_bgr, 1, 0, sensor.exposureGain(1, 2.0), color);
  EXPECT_EQ(cv::norm(color, render.color_bgr, cv::NORM_INF), 0.0);
}

TEST(SensorModel, ColourNoiseHasTheConfiguredSpread) {
  SensorParams params = SensorParams::exact();
  params.color_noise_std = 3.0;
  const SensorModel sensor(params);
  const RenderOutput render = flatRender(1.0);
  cv::Mat color;
  sensor.measureColor(render.color_bgr, 5, 0, 1.0, color);
  cv::Mat difference;
  cv::subtract(color, render.color_bgr, difference, cv::noArray(), CV_32FC3);
  cv::Scalar mean, stddev;
  cv::meanStdDev(difference.reshape(1), mean, stddev);
  EXPECT_NEAR(mean[0], 0.0, 0.05);
  // Rounding to integers adds 1/12 to the variance.
  EXPECT_NEAR(stddev[0], std::sqrt(9.0 + 1.0 / 12.0), 0.05);
}

TEST(SensorModel, ExposureGainVariesWithinTheConfiguredBound) {
  SensorParams params = SensorParams::exact();
  params.exposure_variation = 0.15;
  const SensorModel sensor(params);
  double lo = 10.0;
  double hi = 0.0;
  for (double t = 0.0; t < 60.0; t += 0.1) {
    lo = std::min(lo, sensor.exposureGain(9, t));
    hi = std::max(hi, sensor.exposureGain(9, t));
  }
  EXPECT_GE(lo, 0.85);
  EXPECT_LE(hi, 1.15);
  EXPECT_GT(hi - lo, 0.1);
}

TEST(SensorModel, TheSameFrameGetsTheSameNoise) {
  const SensorModel sensor{SensorParams()};
  const RenderOutput render = flatRender(2.0);
  const cv::Mat a = sensor.measureDepth(render, 4, 17);
  const cv::Mat b = sensor.measureDepth(render, 4, 17);
  const cv::Mat c = sensor.measureDepth(render, 4, 18);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace slamd::synth
