#include "slamd/synth/texture.hpp"

#include <gtest/gtest.h>
#include <opencv2/features2d.hpp>

#include "synth_test_support.hpp"

namespace slamd::synth {
namespace {

TEST(Texture, TheSameSeedGivesTheSameTexture) {
  const Texture a = Texture::generate(TextureKind::kPlaster, 0.7, 123, 256);
  const Texture b = Texture::generate(TextureKind::kPlaster, 0.7, 123, 256);
  const Texture c = Texture::generate(TextureKind::kPlaster, 0.7, 124, 256);
  ASSERT_EQ(a.levelCount(), b.levelCount());
  for (int level = 0; level < a.levelCount(); ++level) {
    EXPECT_EQ(cv::norm(a.level(level), b.level(level), cv::NORM_INF), 0.0);
  }
  EXPECT_GT(cv::norm(a.level(0), c.level(0), cv::NORM_L1), 0.0);
  EXPECT_EQ(a.level(a.levelCount() - 1).cols, 4);
}

TEST(Texture, RejectsBadSizesAndDensitiesNamingTheValue) {
  try {
    Texture::generate(TextureKind::kPoster, 0.5, 1, 300);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("300"), std::string::npos) << error.what();
  }
  EXPECT_THROW(Texture::generate(TextureKind::kPlaster, 1.5, 1, 64), std::invalid_argument);
  EXPECT_THROW(Texture::fromImage(cv::Mat(10, 20, CV_8UC3)), std::invalid_argument);
}

TEST(Texture, WrappedSamplingTilesSeamlesslyAndClampedSamplingStops) {
  const Texture texture = Texture::generate(TextureKind::kFloorTiles, 0.5, 9, 64);
  const cv::Vec3f a = texture.sample(3.0, 5.0, 0, true);
  const cv::Vec3f b = texture.sample(3.0 + 64.0 * 1000.0, 5.0 - 64.0 * 7.0, 0, true);
  EXPECT_EQ(cv::norm(a - b), 0.0);
  const cv::Vec3f edge = texture.sample(63.0, 10.0, 0, false);
  const cv::Vec3f beyond = texture.sample(500.0, 10.0, 0, false);
  EXPECT_EQ(cv::norm(edge - beyond), 0.0);
}

int fastCorners(const cv::Mat& gray) {
  std::vector<cv::KeyPoint> corners;
  cv::FAST(gray, corners, 20, true);
  return static_cast<int>(corners.size());
}

TEST(Texture, DensityControlsHowManyCornersTheCorridorOffers) {
  const auto corners_at = [](const std::string& density) {
    const auto source = test::makeSyntheticSource(
        "corridor", {"synthetic.sensor.exact=true", "synthetic.texture_density=" + density,
                     "synthetic.doors=false", "synthetic.posters=false"});
    int total = 0;
    for (int index : {0, 200, 400}) total += fastCorners(source->renderFrame(index)->gray);
    return total;
  };
  const int featureless = corners_at("0.0");
  const int rich = corners_at("1.0");
  RecordProperty("fast_corners_density_0", featureless);
  RecordProperty("fast_corners_density_1", rich);
  EXPECT_GT(rich, 3 * featureless) << "density 0: " << featureless << ", density 1: " << rich;
  EXPECT_GT(rich / 3, 300);
}

TEST(Texture, PostersGiveCornersEvenOnFeaturelessWalls) {
  const auto source = test::makeSyntheticSource(
      "room", {"synthetic.sensor.exact=true", "synthetic.texture_density=0.0"});
  int total = 0;
  for (int index : {0, 300, 600}) total += fastCorners(source->renderFrame(index)->gray);
  EXPECT_GT(total / 3, 150);
}

}  // namespace
}  // namespace slamd::synth
