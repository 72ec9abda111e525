#pragma once
// Helpers for tests of keyframes that follow corrections: comparing two maps voxel by voxel,
// integrating keyframes at drifted poses, and the reference map integrated at given poses.

#include <cmath>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include "box_room.hpp"
#include "slamd/mapping/mapper.hpp"

namespace slamd::test {

/// Every voxel of `expected` is in `actual` with the same log-odds (to `tolerance`), and `actual`
/// has no voxel `expected` lacks. Pruned blocks compare by the value they hold.
inline void expectSameVoxels(const octomap::OcTree& actual, const octomap::OcTree& expected,
                             float tolerance = 1e-3f) {
  std::size_t mismatches = 0;
  for (auto it = expected.begin_leafs(); it != expected.end_leafs(); ++it) {
    const octomap::OcTreeNode* other =
        actual.search(it.getKey(), static_cast<unsigned>(it.getDepth()));
    if (other == nullptr || std::abs(other->getLogOdds() - it->getLogOdds()) > tolerance) {
      ++mismatches;
    }
  }
  std::size_t extra = 0;
  for (auto it = actual.begin_leafs(); it != actual.end_leafs(); ++it) {
    if (expected.search(it.getKey(), static_cast<unsigned>(it.getDepth())) == nullptr) ++extra;
  }
  EXPECT_EQ(mismatches, 0u) << "of " << expected.getNumLeafNodes() << " expected voxels";
  EXPECT_EQ(extra, 0u) << "voxels left where nothing should be";
}

/// Keyframes of a look-around at `truth`, integrated at poses that drift by a few centimetres and
/// a quarter of a degree more with each keyframe (the first does not drift), as odometry drifts
/// before a loop closes; returns the corrected (true) poses by id.
inline std::vector<std::pair<std::int64_t, SE3>> integrateDrifted(Mapper& mapper,
                                                                  const BoxRoom& room,
                                                                  const std::vector<SE3>& truth) {
  std::vector<std::pair<std::int64_t, SE3>> corrected;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const RgbdFrame frame = room.render(truth[i]);
    SE3 drifted = truth[i];
    drifted.translation() += static_cast<double>(i) * Eigen::Vector3d(0.03, 0.0, 0.02);
    drifted.linear() = Eigen::AngleAxisd(0.004 * static_cast<double>(i), Eigen::Vector3d::UnitY()) *
                       drifted.linear();
    const auto id = static_cast<std::int64_t>(i);
    EXPECT_TRUE(mapper.integrate(frame, drifted, id).keyframe_cloud_kept);
    corrected.emplace_back(id, truth[i]);
  }
  return corrected;
}

/// The map of the frames seen from `truth`, integrated directly at `poses` (default: `truth`).
inline std::unique_ptr<Mapper> mapAt(const BoxRoom& room, const std::vector<SE3>& truth,
                                     const MappingConfig& config, std::vector<SE3> poses = {}) {
  if (poses.empty()) poses = truth;
  auto reference = std::make_unique<Mapper>(config);
  for (std::size_t i = 0; i < truth.size(); ++i) {
    reference->integrate(room.render(truth[i]), poses[i], static_cast<std::int64_t>(i));
  }
  return reference;
}

}  // namespace slamd::test
