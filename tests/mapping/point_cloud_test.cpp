#include "slamd/mapping/point_cloud.hpp"

#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "slamd/mapping/mapping_config.hpp"

namespace slamd {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

CameraIntrinsics tinyCamera(int width, int height) {
  CameraIntrinsics K;
  K.width = width;
  K.height = height;
  K.fx = K.fy = 10.0;
  K.cx = (width - 1) / 2.0;
  K.cy = (height - 1) / 2.0;
  return K;
}

TEST(MappingConfig, DefaultsMatchTheIssue) {
  Config config;
  const MappingConfig c = MappingConfig::load(config);
  EXPECT_DOUBLE_EQ(c.resolution_m, 0.05);
  EXPECT_DOUBLE_EQ(c.max_range_m, 4.0);
  EXPECT_DOUBLE_EQ(c.prob_hit, 0.7);
  EXPECT_DOUBLE_EQ(c.prob_miss, 0.4);
  EXPECT_DOUBLE_EQ(c.clamp_min, 0.12);
  EXPECT_DOUBLE_EQ(c.clamp_max, 0.97);
  EXPECT_DOUBLE_EQ(c.voxel_filter_m, 0.05);
  EXPECT_EQ(c.voxel_filter_mode, VoxelFilterMode::kNearestToCentre);
  EXPECT_TRUE(c.validationError().empty());
}

TEST(MappingConfig, RejectsOutOfRangeAndInconsistentValues) {
  for (const char* bad :
       {"mapping.resolution_m=0", "mapping.prob_hit=0.3", "mapping.voxel_filter_mode=median",
        "mapping.pixel_stride=0", "mapping.projection.min_height_m=2", "mapping.max_depth_m=0.05",
        "mapping.occupancy_threshold=0.98", "mapping.insertion=fast"}) {
    Config config;
    config.applyOverride(bad);
    EXPECT_THROW(MappingConfig::load(config), ConfigError) << bad;
  }
  Config config;
  config.applyOverride("mapping.voxel_filter_mode=centroid");
  config.applyOverride("mapping.insertion=octomap_discrete");
  config.applyOverride("mapping.projection.up_axis=+z");
  const MappingConfig c = MappingConfig::load(config);
  EXPECT_EQ(c.voxel_filter_mode, VoxelFilterMode::kCentroid);
  EXPECT_EQ(c.insertion, InsertionMethod::kOctomapDiscrete);
  EXPECT_EQ(c.up_axis, UpAxis::kPlusZ);
}

TEST(DepthToCloud, DropsAndCountsEveryKindOfInvalidDepth) {
  cv::Mat depth = (cv::Mat_<float>(2, 4) << 1.0f, kNaN, 0.0f, -1.0f,  //
                   kInf, -kInf, 0.05f, 50.0f);
  PointCloud cloud;
  DepthCloudStats stats;
  DepthToCloudOptions options;
  options.min_depth_m = 0.1;
  options.max_depth_m = 10.0;
  ASSERT_EQ(depthToCloud(depth, cv::Mat(), tinyCamera(4, 2), options, cloud, stats),
            DepthCloudStatus::kOk);
  ASSERT_EQ(cloud.size(), 1u);
  EXPECT_EQ(stats.valid, 1);
  EXPECT_EQ(stats.nan, 1);
  EXPECT_EQ(stats.zero, 1);
  EXPECT_EQ(stats.negative, 1);
  EXPECT_EQ(stats.infinite, 2);
  EXPECT_EQ(stats.too_near, 1);
  EXPECT_EQ(stats.too_far, 1);
  EXPECT_EQ(stats.rejected(), 7);
  EXPECT_FALSE(cloud.hasColor());
  // Pixel (0, 0) with cx = 1.5, cy = 0.5, f = 10 at z = 1.
  EXPECT_NEAR(cloud.points[0].x(), -0.15f, 1e-6f);
  EXPECT_NEAR(cloud.points[0].y(), -0.05f, 1e-6f);
  EXPECT_FLOAT_EQ(cloud.points[0].z(), 1.0f);
}

TEST(DepthToCloud, RejectsWrongTypesSizesAndIntrinsics) {
  PointCloud cloud;
  DepthCloudStats stats;
  const DepthToCloudOptions options;
  EXPECT_EQ(depthToCloud(cv::Mat(2, 4, CV_16UC1, cv::Scalar(1000)), cv::Mat(), tinyCamera(4, 2),
                         options, cloud, stats),
            DepthCloudStatus::kBadDepthType);
  EXPECT_EQ(depthToCloud(cv::Mat(), cv::Mat(), tinyCamera(4, 2), options, cloud, stats),
            DepthCloudStatus::kBadDepthType);
  EXPECT_EQ(depthToCloud(cv::Mat(3, 4, CV_32FC1, cv::Scalar(1.0)), cv::Mat(), tinyCamera(4, 2),
                         options, cloud, stats),
            DepthCloudStatus::kSizeMismatch);
  CameraIntrinsics bad = tinyCamera(4, 2);
  bad.fx = std::nan("");
  EXPECT_EQ(
      depthToCloud(cv::Mat(2, 4, CV_32FC1, cv::Scalar(1.0)), cv::Mat(), bad, options, cloud, stats),
      DepthCloudStatus::kBadIntrinsics);
  EXPECT_TRUE(cloud.empty());
}

TEST(DepthToCloud, AttachesColourOnlyWhenItMatchesAndHonoursTheStride) {
  const cv::Mat depth(4, 6, CV_32FC1, cv::Scalar(2.0));
  const cv::Mat color(4, 6, CV_8UC3, cv::Scalar(10, 20, 30));
  PointCloud cloud;
  DepthCloudStats stats;
  DepthToCloudOptions options;
  options.pixel_stride = 2;
  ASSERT_EQ(depthToCloud(depth, color, tinyCamera(6, 4), options, cloud, stats),
            DepthCloudStatus::kOk);
  EXPECT_EQ(cloud.size(), 6u);  // 3 columns x 2 rows
  ASSERT_TRUE(cloud.hasColor());
  EXPECT_EQ(cloud.colors_bgr[0], (ColorBgr{10, 20, 30}));
  ASSERT_EQ(depthToCloud(depth, cv::Mat(2, 2, CV_8UC3), tinyCamera(6, 4), options, cloud, stats),
            DepthCloudStatus::kOk);
  EXPECT_FALSE(cloud.hasColor());
  EXPECT_FALSE(stats.color_used);
}

using CubeIndex = std::tuple<long, long, long>;

CubeIndex cubeOf(const Eigen::Vector3f& p, double voxel) {
  const Eigen::Vector3d q = p.cast<double>() / voxel;
  return {static_cast<long>(std::floor(q.x())), static_cast<long>(std::floor(q.y())),
          static_cast<long>(std::floor(q.z()))};
}

TEST(VoxelGridFilter, KeepsOnePointPerCubeNearestToItsCentre) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> coord(-1.0f, 1.0f);
  PointCloud input;
  for (int i = 0; i < 20000; ++i)
    input.points.emplace_back(coord(rng), coord(rng), coord(rng) + 2.0f);
  const double voxel = 0.2;
  VoxelGridFilter filter;
  PointCloud output;
  filter.apply(input, voxel, VoxelFilterMode::kNearestToCentre, output);
  // Brute force: per cube, the input point nearest the centre.
  std::map<CubeIndex, std::pair<float, Eigen::Vector3f>> best;
  for (const auto& p : input.points) {
    const CubeIndex c = cubeOf(p, voxel);
    const Eigen::Vector3f centre((std::get<0>(c) + 0.5f) * 0.2f, (std::get<1>(c) + 0.5f) * 0.2f,
                                 (std::get<2>(c) + 0.5f) * 0.2f);
    const float d2 = (p - centre).squaredNorm();
    auto it = best.find(c);
    if (it == best.end() || d2 < it->second.first) best[c] = {d2, p};
  }
  ASSERT_EQ(output.size(), best.size());
  std::set<CubeIndex> seen;
  for (const auto& p : output.points) {
    const CubeIndex c = cubeOf(p, voxel);
    EXPECT_TRUE(seen.insert(c).second);
    EXPECT_EQ(p, best.at(c).second);
  }
}

TEST(VoxelGridFilter, CentroidAveragesPointsAndColours) {
  PointCloud input;
  input.points = {{0.01f, 0.01f, 1.01f}, {0.03f, 0.03f, 1.03f}, {0.51f, 0.0f, 1.0f}};
  input.colors_bgr = {{0, 0, 0}, {100, 50, 20}, {7, 7, 7}};
  VoxelGridFilter filter;
  PointCloud output;
  filter.apply(input, 0.05, VoxelFilterMode::kCentroid, output);
  ASSERT_EQ(output.size(), 2u);
  EXPECT_NEAR(output.points[0].x(), 0.02f, 1e-6f);
  EXPECT_NEAR(output.points[0].z(), 1.02f, 1e-6f);
  EXPECT_EQ(output.colors_bgr[0], (ColorBgr{50, 25, 10}));
  EXPECT_EQ(output.colors_bgr[1], (ColorBgr{7, 7, 7}));
}

TEST(VoxelGridFilter, DropsNonFinitePointsAndIsDeterministic) {
  PointCloud input;
  input.points = {{kNaN, 0, 1}, {0, kInf, 1}, {0.1f, 0.1f, 1.0f}, {1e30f, 0, 0}};
  VoxelGridFilter filter;
  PointCloud a;
  filter.apply(input, 0.05, VoxelFilterMode::kNearestToCentre, a);
  EXPECT_EQ(a.size(), 1u);
  EXPECT_EQ(filter.droppedLastCall(), 3u);
  filter.apply(input, 0.0, VoxelFilterMode::kNearestToCentre, a);  // disabled: copy finite ones
  EXPECT_EQ(a.size(), 2u);
}

TEST(VoxelGridFilter, ReducesAVgaFrameToTensOfThousandsOfPoints) {
  // 300,000 points on a 3 x 2.25 m plane 2 m away: 5 cm cubes leave about 60 x 45 of them.
  PointCloud input;
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> noise(-0.002f, 0.002f);
  for (int v = 0; v < 480; ++v) {
    for (int u = 0; u < 640; ++u) {
      input.points.emplace_back((u - 319.5f) * 2.0f / 525.0f, (v - 239.5f) * 2.0f / 525.0f,
                                2.0f + noise(rng));
    }
  }
  VoxelGridFilter filter;
  PointCloud output;
  filter.apply(input, 0.05, VoxelFilterMode::kNearestToCentre, output);
  EXPECT_GT(output.size(), 2500u);
  EXPECT_LT(output.size(), 6000u);
}

}  // namespace
}  // namespace slamd
