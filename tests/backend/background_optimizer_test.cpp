#include "slamd/backend/background_optimizer.hpp"

#include <cmath>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "pose_graph_rings.hpp"

namespace slamd {
namespace {

double maxDifferenceM(const PoseGraph& a, const PoseGraph& b) {
  double worst = 0.0;
  for (std::int64_t id : a.nodeIds()) {
    worst = std::max(worst, (a.pose(id).translation() - b.pose(id).translation()).norm());
  }
  return worst;
}

TEST(BackgroundOptimizer, GivesTheSolutionOfOptimisingInPlaceAndTakesOneJobAtATime) {
  std::mt19937 rng(7);
  const PoseGraph ring = test::makeRing(300, rng).graph;
  PoseGraph in_place = ring;
  const PoseGraphResult expected = in_place.optimize(PoseGraphOptions());
  ASSERT_EQ(expected.status, OptimizationStatus::kConverged);

  BackgroundOptimizer optimizer;
  EXPECT_FALSE(optimizer.busy());
  EXPECT_FALSE(optimizer.poll().has_value());
  FullOptimizationJob job;
  job.graph = ring;
  job.newest_id = 299;
  ASSERT_TRUE(optimizer.submit(job));
  EXPECT_TRUE(optimizer.busy());
  // A second job waits until the first one's result has been collected.
  EXPECT_FALSE(optimizer.submit(job));
  const std::optional<FullOptimizationJob> done = optimizer.wait();
  ASSERT_TRUE(done.has_value());
  EXPECT_TRUE(done->done);
  EXPECT_EQ(done->result.status, OptimizationStatus::kConverged);
  EXPECT_EQ(done->result.iterations, expected.iterations);
  EXPECT_LT(maxDifferenceM(done->graph, in_place), 1e-12);
  EXPECT_FALSE(optimizer.busy());
  EXPECT_FALSE(optimizer.poll().has_value());
  EXPECT_FALSE(optimizer.wait().has_value());

  // The worker serves the next job; poll() hands it over once, when it is done.
  ASSERT_TRUE(optimizer.submit(job));
  std::optional<FullOptimizationJob> polled;
  while (!(polled = optimizer.poll())) std::this_thread::yield();
  EXPECT_LT(maxDifferenceM(polled->graph, in_place), 1e-12);
  EXPECT_FALSE(optimizer.poll().has_value());
}

TEST(BackgroundOptimizer, DestroyingItWithAJobInFlightJoinsTheWorker) {
  std::mt19937 rng(8);
  FullOptimizationJob job;
  job.graph = test::makeRing(500, rng).graph;
  job.newest_id = 499;
  BackgroundOptimizer optimizer;
  ASSERT_TRUE(optimizer.submit(std::move(job)));
  // The destructor joins the worker (ThreadSanitizer and the leak checker watch this test).
}

TEST(MergeOptimizedCopy, CopiedKeyframesTakeTheirOptimisedPosesAndNewerOnesMoveWithTheNewest) {
  std::mt19937 rng(9);
  PoseGraph live = test::makeRing(120, rng).graph;
  FullOptimizationJob job;
  job.graph = live;
  job.newest_id = 119;
  // While the copy is optimised, the live graph moves on: a local window nudged the newest
  // copied keyframe, and three keyframes were added after it.
  live.setPose(119, live.pose(119) * expSE3(test::noiseSample(rng, 0.01, 0.005)));
  for (int k = 120; k < 123; ++k) {
    const SE3 step = expSE3((Vector6d() << 0.1, 0.0, 0.0, 0.0, 0.0, 0.02).finished());
    live.addNode(k, live.pose(k - 1) * step);
    live.addEdge({k - 1, k, step, test::informationOf(0.01, 0.005), EdgeKind::kOdometry});
  }
  const SE3 T_119_122_before = live.pose(119).inverse() * live.pose(122);

  // Not run yet: nothing moves.
  const PoseGraph before = live;
  EXPECT_FALSE(mergeOptimizedCopy(job, live));
  EXPECT_EQ(maxDifferenceM(live, before), 0.0);

  job.run();
  ASSERT_TRUE(job.done);
  ASSERT_TRUE(mergeOptimizedCopy(job, live));
  for (std::int64_t id : job.graph.nodeIds()) {
    EXPECT_TRUE(live.pose(id).isApprox(job.graph.pose(id), 1e-12)) << "keyframe " << id;
  }
  // The newer keyframes keep their place relative to the newest copied one.
  const SE3 T_119_122_after = live.pose(119).inverse() * live.pose(122);
  EXPECT_TRUE(T_119_122_after.isApprox(T_119_122_before, 1e-9));
  // The loop pulled the end of the ring: the newer keyframes moved with it (by decimetres).
  EXPECT_GT((live.pose(122).translation() - before.pose(122).translation()).norm(), 0.05);

  // A copy whose newest keyframe is gone from the live graph is not merged.
  FullOptimizationJob stale = job;
  stale.newest_id = 500;
  EXPECT_FALSE(mergeOptimizedCopy(stale, live));
}

}  // namespace
}  // namespace slamd
