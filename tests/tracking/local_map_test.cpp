#include "slamd/tracking/local_map.hpp"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace slamd {
namespace {

constexpr double kDepthSigmaCoeff = 0.0015;

/// A keyframe at T_world_camera whose features are the given points (camera frame; NaN = no
/// depth).
KeyframePtr keyframeWith(std::int64_t id, const SE3& T_world_camera,
                         const std::vector<Eigen::Vector3d>& points) {
  auto keyframe = std::make_shared<Keyframe>();
  keyframe->id = id;
  keyframe->T_world_camera = T_world_camera;
  for (const Eigen::Vector3d& p : points) {
    keyframe->features.keypoints.emplace_back(0.0f, 0.0f, 31.0f);
    keyframe->features.points.push_back(p);
    keyframe->features.pixels.emplace_back(0.0, 0.0);
    keyframe->features.scale.push_back(1.0f);
  }
  return keyframe;
}

SE3 translated(double x) {
  SE3 T = SE3::Identity();
  T.translation() = Eigen::Vector3d(x, 0.0, 0.0);
  return T;
}

const double kNan = std::numeric_limits<double>::quiet_NaN();

TEST(LocalMap, MatchedFeaturesJoinTheirLandmarkAndTheRestStartNewOnes) {
  LocalMap map(kDepthSigmaCoeff);
  // Keyframe 0 at the origin sees three points, the second without depth.
  map.addKeyframe(keyframeWith(0, SE3::Identity(), {{0, 0, 1}, {1, 0, kNan}, {0, 1, 2}}), {});
  const std::vector<std::int64_t> first = map.landmarksOf(0);
  ASSERT_EQ(first.size(), 3u);
  EXPECT_GE(first[0], 0);
  EXPECT_EQ(first[1], -1);  // no depth: no landmark
  EXPECT_GE(first[2], 0);
  EXPECT_EQ(map.numLandmarks(), 2u);

  // Keyframe 1, 0.1 m to the right, sees point (0, 0, 1) again (matched to its landmark) and a
  // new one.
  map.addKeyframe(keyframeWith(1, translated(0.1), {{-0.1, 0, 1}, {0.5, 0.5, 3}}), {first[0], -1});
  const std::vector<std::int64_t>& second = map.landmarksOf(1);
  EXPECT_EQ(second[0], first[0]);
  EXPECT_NE(second[1], first[2]);
  EXPECT_EQ(map.numLandmarks(), 3u);
  const MapLandmark* shared = map.landmark(first[0]);
  ASSERT_NE(shared, nullptr);
  EXPECT_EQ(shared->observations.size(), 2u);
  EXPECT_EQ(shared->representative().keyframe_id, 1);  // the latest view
  EXPECT_EQ(shared->representative().feature_index, 0);
  EXPECT_NEAR((shared->p_world - Eigen::Vector3d(0, 0, 1)).norm(), 0.0, 1e-12);
}

TEST(LocalMap, TheRevisionChangesExactlyWhenKeyframesOrObservationsDo) {
  LocalMap map(kDepthSigmaCoeff);
  std::uint64_t revision = map.revision();
  auto changed = [&] {
    const bool different = map.revision() != revision;
    revision = map.revision();
    return different;
  };
  const KeyframePtr first = keyframeWith(0, SE3::Identity(), {{0, 0, 1}, {0, 1, 2}});
  map.addKeyframe(first, {});
  EXPECT_TRUE(changed());
  map.addKeyframe(first, {});  // already in the map: ignored
  EXPECT_FALSE(changed());
  map.addKeyframe(nullptr, {});
  EXPECT_FALSE(changed());
  map.addKeyframe(keyframeWith(1, translated(0.1), {{-0.1, 0, 1}}), {map.landmarksOf(0)[0]});
  EXPECT_TRUE(changed());  // a new observation of landmark 0: its representative view moved
  map.removeKeyframe(7);   // not in the map
  EXPECT_FALSE(changed());
  map.removeKeyframe(1);
  EXPECT_TRUE(changed());
  map.clear();
  EXPECT_TRUE(changed());
}

TEST(LocalMap, ThePositionIsTheInverseVarianceMeanAndFollowsRemovals) {
  LocalMap map(kDepthSigmaCoeff);
  // One landmark seen at 1 m and at 2 m depth, 1 cm apart (odometry error): sigma_z grows with
  // z^2, so the near view weighs 16 times more.
  map.addKeyframe(keyframeWith(0, SE3::Identity(), {{0, 0, 1}}), {});
  const std::int64_t id = map.landmarksOf(0)[0];
  SE3 back = SE3::Identity();
  back.translation() = Eigen::Vector3d(0.0, 0.0, -1.0);
  map.addKeyframe(keyframeWith(1, back, {{0.01, 0, 2}}), {id});
  const Eigen::Vector3d expected =
      (16.0 * Eigen::Vector3d(0, 0, 1) + Eigen::Vector3d(0.01, 0, 1)) / 17.0;
  EXPECT_NEAR((map.landmark(id)->p_world - expected).norm(), 0.0, 1e-9);

  // The near keyframe leaves the window: the far view alone places the landmark, and represents
  // it.
  map.removeKeyframe(0);
  ASSERT_NE(map.landmark(id), nullptr);
  EXPECT_NEAR((map.landmark(id)->p_world - Eigen::Vector3d(0.01, 0, 1)).norm(), 0.0, 1e-9);
  EXPECT_EQ(map.landmark(id)->representative().keyframe_id, 1);
  // The last one leaves: the landmark goes with it.
  map.removeKeyframe(1);
  EXPECT_EQ(map.landmark(id), nullptr);
  EXPECT_EQ(map.numLandmarks(), 0u);
  EXPECT_EQ(map.numKeyframes(), 0u);
}

TEST(LocalMap, CovisibleKeyframesShareLandmarksMostSharedFirst) {
  LocalMap map(kDepthSigmaCoeff);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 20; ++i) points.emplace_back(0.1 * i, 0.0, 2.0);
  map.addKeyframe(keyframeWith(0, SE3::Identity(), points), {});
  const std::vector<std::int64_t> ids = map.landmarksOf(0);
  // Keyframe 1 shares 15 landmarks with 0, keyframe 2 shares 5 with 0 and 5 with 1, keyframe 3
  // none.
  std::vector<std::int64_t> share15(ids.begin(), ids.begin() + 15);
  map.addKeyframe(keyframeWith(1, SE3::Identity(), {points.begin(), points.begin() + 15}), share15);
  std::vector<std::int64_t> share5(ids.begin(), ids.begin() + 5);
  map.addKeyframe(keyframeWith(2, SE3::Identity(), {points.begin(), points.begin() + 5}), share5);
  map.addKeyframe(keyframeWith(3, SE3::Identity(), {points.begin(), points.begin() + 5}), {});

  EXPECT_EQ(map.covisibleKeyframes(0, 1, 10), (std::vector<std::int64_t>{1, 2}));
  EXPECT_EQ(map.covisibleKeyframes(0, 10, 10), (std::vector<std::int64_t>{1}));
  EXPECT_EQ(map.covisibleKeyframes(0, 1, 1), (std::vector<std::int64_t>{1}));
  EXPECT_TRUE(map.covisibleKeyframes(3, 1, 10).empty());
  EXPECT_TRUE(map.covisibleKeyframes(42, 1, 10).empty());  // not in the map

  // Two features of one keyframe matched to one landmark: the second starts its own.
  map.addKeyframe(keyframeWith(4, SE3::Identity(), {points[19], points[19]}), {ids[19], ids[19]});
  EXPECT_EQ(map.landmarksOf(4)[0], ids[19]);
  EXPECT_NE(map.landmarksOf(4)[1], ids[19]);
  EXPECT_EQ(map.landmark(ids[19])->observations.size(), 2u);
}

}  // namespace
}  // namespace slamd
