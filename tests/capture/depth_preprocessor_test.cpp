#include "slamd/capture/depth_preprocessor.hpp"

#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

namespace slamd {
namespace {

const float kNan = std::numeric_limits<float>::quiet_NaN();

DepthPreprocessorConfig onlySteps(bool range, bool flying, bool bilateral) {
  DepthPreprocessorConfig config;
  config.range_gate = range;
  config.flying_pixels = flying;
  config.bilateral = bilateral;
  return config;
}

TEST(DepthPreprocessor, RangeGateRemovesDepthOutsideTheLimits) {
  DepthPreprocessorConfig config = onlySteps(true, false, false);
  config.min_depth_m = 0.8;
  config.max_depth_m = 3.0;
  DepthPreprocessor pre(config);
  cv::Mat depth = (cv::Mat_<float>(1, 5) << 0.5f, 0.8f, 2.0f, 3.0f, 3.5f);
  depth.at<float>(0, 2) = kNan;
  EXPECT_EQ(pre.rangeGate(depth), 2);
  EXPECT_TRUE(std::isnan(depth.at<float>(0, 0)));
  EXPECT_FLOAT_EQ(depth.at<float>(0, 1), 0.8f);
  EXPECT_TRUE(std::isnan(depth.at<float>(0, 2)));
  EXPECT_FLOAT_EQ(depth.at<float>(0, 3), 3.0f);
  EXPECT_TRUE(std::isnan(depth.at<float>(0, 4)));
}

TEST(DepthPreprocessor, FlyingPixelBetweenForegroundAndBackgroundIsRemoved) {
  // Columns 0-3 at 1 m (foreground), column 4 at 1.5 m (flying), columns 5-9 at 2 m.
  cv::Mat depth(5, 10, CV_32FC1, cv::Scalar(2.0f));
  depth.colRange(0, 4).setTo(1.0f);
  depth.col(4).setTo(1.5f);
  DepthPreprocessor pre(onlySteps(false, true, false));
  pre.removeFlyingPixels(depth);
  for (int r = 0; r < 5; ++r) {
    EXPECT_TRUE(std::isnan(depth.at<float>(r, 4))) << r;
    EXPECT_FLOAT_EQ(depth.at<float>(r, 3), 1.0f) << "a true foreground edge is kept";
    EXPECT_FLOAT_EQ(depth.at<float>(r, 5), 2.0f) << "a true background edge is kept";
  }
}

TEST(DepthPreprocessor, IsolatedSpeckleIsRemovedAndNanNeighboursIgnored) {
  cv::Mat depth(5, 5, CV_32FC1, cv::Scalar(kNan));
  depth.at<float>(2, 2) = 1.0f;  // alone among NaN
  depth.at<float>(0, 0) = 3.0f;
  depth.at<float>(0, 1) = 3.01f;
  depth.at<float>(1, 0) = 3.02f;
  DepthPreprocessor pre(onlySteps(false, true, false));
  EXPECT_EQ(pre.removeFlyingPixels(depth), 1);
  EXPECT_TRUE(std::isnan(depth.at<float>(2, 2)));
  EXPECT_FLOAT_EQ(depth.at<float>(0, 0), 3.0f);
}

TEST(DepthPreprocessor, BilateralSmoothsNoiseButKeepsDepthSteps) {
  std::mt19937 rng(42);
  std::normal_distribution<float> noise(0.0f, 0.005f);
  cv::Mat depth(40, 40, CV_32FC1);
  for (int r = 0; r < 40; ++r) {
    for (int c = 0; c < 40; ++c) depth.at<float>(r, c) = (c < 20 ? 1.0f : 2.0f) + noise(rng);
  }
  depth.at<float>(5, 5) = kNan;
  const cv::Mat before = depth.clone();
  DepthPreprocessor pre(onlySteps(false, false, true));
  pre.bilateral(depth);
  auto spread = [](const cv::Mat& m, int c0, int c1) {
    cv::Scalar mean, stddev;
    cv::Mat region = m(cv::Rect(c0, 10, c1 - c0, 20)).clone();
    cv::meanStdDev(region, mean, stddev);
    return stddev[0];
  };
  EXPECT_LT(spread(depth, 2, 17), 0.6 * spread(before, 2, 17)) << "noise is reduced";
  for (int r = 0; r < 40; ++r) {
    EXPECT_NEAR(depth.at<float>(r, 19), 1.0f, 0.02f) << "no blur across the 1 m step";
    EXPECT_NEAR(depth.at<float>(r, 20), 2.0f, 0.03f);
  }
  EXPECT_TRUE(std::isnan(depth.at<float>(5, 5))) << "holes stay holes";
  EXPECT_FALSE(std::isnan(depth.at<float>(5, 6)));
}

TEST(DepthPreprocessor, ProcessTimesEachEnabledStep) {
  cv::Mat depth(48, 64, CV_32FC1, cv::Scalar(1.0f));
  DepthPreprocessor pre(onlySteps(true, false, true));
  const DepthPreprocessTimings t = pre.process(depth);
  EXPECT_GT(t.range_gate_ns, 0);
  EXPECT_EQ(t.flying_pixels_ns, 0);
  EXPECT_GT(t.bilateral_ns, 0);
  EXPECT_EQ(t.totalNs(), t.range_gate_ns + t.bilateral_ns);
}

TEST(DepthPreprocessorConfig, RejectsAnEmptyRange) {
  Config config;
  config.set("capture.preprocess.min_depth_m", "3.0");
  config.set("capture.preprocess.max_depth_m", "1.0");
  EXPECT_THROW(DepthPreprocessorConfig::load(config), ConfigError);
}

}  // namespace
}  // namespace slamd
