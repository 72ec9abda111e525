#include "slamd/pipeline/pipeline.hpp"

#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numeric>
#include <thread>

#include <gtest/gtest.h>

#include "slamd/common/log.hpp"
#include "test_helpers.hpp"

namespace slamd {
namespace {

using namespace std::chrono_literals;

// Real computations for the three stages: a deterministic pseudo-image per item, its blurred
// checksum, and a summary string. Cheap enough for 10^3 items, expensive enough to interleave.
struct Image {
  std::uint64_t id = 0;
  std::vector<double> pixels;
};

Image makeImage(std::uint64_t id) {
  Image image{id, std::vector<double>(256)};
  std::uint64_t state = id * 6364136223846793005ULL + 1442695040888963407ULL;
  for (auto& p : image.pixels) {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    p = static_cast<double>(state >> 40) / static_cast<double>(1ULL << 24);
  }
  return image;
}

struct Features {
  std::uint64_t id = 0;
  double energy = 0.0;
};

std::optional<Features> extract(Image image) {
  double energy = 0.0;
  for (std::size_t i = 1; i + 1 < image.pixels.size(); ++i) {
    const double smoothed =
        0.25 * image.pixels[i - 1] + 0.5 * image.pixels[i] + 0.25 * image.pixels[i + 1];
    energy += smoothed * smoothed;
  }
  return Features{image.id, energy};
}

std::string summarize(const Features& f) {
  return std::to_string(f.id) + ":" + std::to_string(std::llround(f.energy * 1e6));
}

class PipelineTest : public ::testing::Test {
 protected:
  void SetUp() override { setLogLevel(LogLevel::kError); }
  void TearDown() override { setLogLevel(LogLevel::kInfo); }
};

// Builds source -> extract -> summarize -> collect with the given policies; runs to completion.
std::vector<std::string> runThreeStage(PipelineMode mode, std::uint64_t items,
                                       EdgeOptions first_edge, EdgeOptions second_edge,
                                       std::vector<StageStats>* stats_out = nullptr) {
  Pipeline pipeline(mode);
  std::uint64_t next = 0;
  std::vector<std::string> results;  // written only by the sink thread; read after join
  auto images = pipeline.addSource<Image>("source", [&]() -> SourceStep<Image> {
    if (next == items) return SourceStep<Image>::end();
    return SourceStep<Image>::of(makeImage(next++));
  });
  auto features = pipeline.addStage<Image, Features>("extract", images, first_edge, extract);
  auto summaries = pipeline.addStage<Features, std::string>(
      "summarize", features, second_edge,
      [](Features f) -> std::optional<std::string> { return summarize(f); });
  pipeline.addSink<std::string>("collect", summaries, {8, EdgePolicy::kBackpressure},
                                [&](std::string s) { results.push_back(std::move(s)); });
  pipeline.start();
  if (mode == PipelineMode::kSequential) {
    pipeline.run();
  } else {
    const bool finished = pipeline.waitUntilFinished(std::chrono::steady_clock::now() + 60s);
    EXPECT_TRUE(finished);
    pipeline.stop(1s);
  }
  if (stats_out) *stats_out = pipeline.stats();
  return results;
}

TEST_F(PipelineTest, BackpressureKeepsOrderAndDeliversEverything) {
  std::vector<StageStats> stats;
  const auto results = runThreeStage(PipelineMode::kThreaded, 2000, {4, EdgePolicy::kBackpressure},
                                     {2, EdgePolicy::kBackpressure}, &stats);
  ASSERT_EQ(results.size(), 2000u);
  for (std::uint64_t i = 0; i < 2000; ++i) {
    EXPECT_EQ(results[i], summarize(*extract(makeImage(i)))) << i;
  }
  for (const auto& stage : stats) {
    for (const auto& edge : stage.inputs) {
      EXPECT_EQ(edge.dropped, 0u) << stage.name;
      EXPECT_EQ(edge.pushed, 2000u) << stage.name;
      EXPECT_EQ(edge.delivered, 2000u) << stage.name;
    }
    EXPECT_TRUE(stage.finished) << stage.name;
  }
  EXPECT_EQ(stats[0].processed, 2000u);
  EXPECT_GT(stats[1].latency.count, 0u);
}

TEST_F(PipelineTest, SequentialAndThreadedModesGiveIdenticalOutputs) {
  const auto sequential =
      runThreeStage(PipelineMode::kSequential, 500, {2, EdgePolicy::kBackpressure},
                    {2, EdgePolicy::kBackpressure});
  const auto threaded = runThreeStage(PipelineMode::kThreaded, 500, {2, EdgePolicy::kBackpressure},
                                      {2, EdgePolicy::kBackpressure});
  ASSERT_EQ(sequential.size(), 500u);
  EXPECT_EQ(sequential, threaded);
  // In sequential mode no policy ever drops: each item crosses the graph before the next starts.
  const auto sequential_dropping =
      runThreeStage(PipelineMode::kSequential, 500, {1, EdgePolicy::kDropOldest},
                    {1, EdgePolicy::kDrainToNewest});
  EXPECT_EQ(sequential_dropping, sequential);
}

// The consumer blocks on its first item until the source has produced everything, so the number
// of drops is known exactly: capacity C keeps the newest C of the remaining N-1 items.
struct GatedRun {
  std::vector<std::uint64_t> delivered;
  EdgeStats edge;
};

GatedRun runGated(EdgePolicy policy, std::size_t capacity, std::uint64_t items) {
  Pipeline pipeline(PipelineMode::kThreaded);
  test::Gate consumer_holds_first;
  test::Gate source_done;
  std::uint64_t next = 0;
  GatedRun run;
  auto ids = pipeline.addSource<std::uint64_t>("source", [&]() -> SourceStep<std::uint64_t> {
    if (next == 1) {
      EXPECT_TRUE(consumer_holds_first.waitOpen());
    }
    if (next == items) {
      source_done.open();
      return SourceStep<std::uint64_t>::end();
    }
    return SourceStep<std::uint64_t>::of(next++);
  });
  pipeline.addSink<std::uint64_t>("slow", ids, {capacity, policy}, [&](std::uint64_t id) {
    if (id == 0) {
      consumer_holds_first.open();
      EXPECT_TRUE(source_done.waitOpen());
    }
    run.delivered.push_back(id);
  });
  pipeline.start();
  EXPECT_TRUE(pipeline.waitUntilFinished(std::chrono::steady_clock::now() + 30s));
  pipeline.stop(1s);
  run.edge = pipeline.stats()[1].inputs[0];
  return run;
}

TEST_F(PipelineTest, DropOldestCountsEveryDropExactly) {
  const GatedRun run = runGated(EdgePolicy::kDropOldest, 4, 100);
  // Item 0 was being processed; items 1..95 were evicted; the newest four remain.
  EXPECT_EQ(run.delivered, (std::vector<std::uint64_t>{0, 96, 97, 98, 99}));
  EXPECT_EQ(run.edge.pushed, 100u);
  EXPECT_EQ(run.edge.dropped, 95u);
  EXPECT_EQ(run.edge.delivered, 5u);
  EXPECT_EQ(run.edge.discarded, 0u);
}

TEST_F(PipelineTest, DrainToNewestSkipsToTheNewestAndCountsExactly) {
  const GatedRun run = runGated(EdgePolicy::kDrainToNewest, 4, 100);
  EXPECT_EQ(run.delivered, (std::vector<std::uint64_t>{0, 99}));
  EXPECT_EQ(run.edge.pushed, 100u);
  EXPECT_EQ(run.edge.dropped, 98u);
  EXPECT_EQ(run.edge.delivered, 2u);
}

TEST_F(PipelineTest, GrowingNeverHoldsUpTheProducerAndDeliversEverythingInOrder) {
  // The source pushes all 100 items while the consumer holds item 0: a backpressure edge of 4
  // would block it, a growing one takes them all.
  const GatedRun run = runGated(EdgePolicy::kGrowing, 4, 100);
  std::vector<std::uint64_t> all(100);
  std::iota(all.begin(), all.end(), 0);
  EXPECT_EQ(run.delivered, all);
  EXPECT_EQ(run.edge.pushed, 100u);
  EXPECT_EQ(run.edge.dropped, 0u);
  EXPECT_EQ(run.edge.delivered, 100u);
  EXPECT_EQ(run.edge.policy, "growing");
}

TEST_F(PipelineTest, OnEnqueueChangesOnlyTheCopyOfItsOwnSink) {
  Pipeline pipeline(PipelineMode::kThreaded);
  std::uint64_t next = 0;
  auto images = pipeline.addSource<Image>("source", [&]() -> SourceStep<Image> {
    if (next == 50) return SourceStep<Image>::end();
    return SourceStep<Image>::of(makeImage(next++));
  });
  std::vector<std::size_t> full_sizes, slim_sizes;  // each written by its sink's thread only
  pipeline.addSink<Image>("full", images, {4, EdgePolicy::kBackpressure},
                          [&](Image image) { full_sizes.push_back(image.pixels.size()); });
  pipeline.addSink<Image>(
      "slim", images, {4, EdgePolicy::kGrowing},
      [&](Image image) { slim_sizes.push_back(image.pixels.size()); },
      [](Image& image) {
        if (image.id % 2 == 1) image.pixels.clear();
      });
  pipeline.start();
  ASSERT_TRUE(pipeline.waitUntilFinished(std::chrono::steady_clock::now() + 30s));
  pipeline.stop(1s);
  ASSERT_EQ(full_sizes.size(), 50u);
  ASSERT_EQ(slim_sizes.size(), 50u);
  for (std::size_t i = 0; i < 50; ++i) {
    EXPECT_EQ(full_sizes[i], 256u) << i;
    EXPECT_EQ(slim_sizes[i], i % 2 == 1 ? 0u : 256u) << i;
  }
}

TEST_F(PipelineTest, DropPoliciesUnderFreeRunningLoadAccountForEveryItem) {
  for (EdgePolicy policy : {EdgePolicy::kDropOldest, EdgePolicy::kDrainToNewest}) {
    std::vector<StageStats> stats;
    const auto results =
        runThreeStage(PipelineMode::kThreaded, 3000, {2, policy}, {1, policy}, &stats);
    const EdgeStats first = stats[1].inputs[0];
    const EdgeStats second = stats[2].inputs[0];
    EXPECT_EQ(first.pushed, 3000u);
    EXPECT_EQ(first.delivered + first.dropped, first.pushed) << edgePolicyName(policy);
    EXPECT_EQ(second.pushed, first.delivered);
    EXPECT_EQ(second.delivered + second.dropped, second.pushed) << edgePolicyName(policy);
    EXPECT_EQ(results.size(), second.delivered);
    // The newest item always gets through, and order is kept among delivered items.
    ASSERT_FALSE(results.empty());
    EXPECT_EQ(results.back(), summarize(*extract(makeImage(2999))));
  }
}

TEST_F(PipelineTest, StopWithDeadlineNeverHangsAndCountsDiscardedItems) {
  Pipeline pipeline(PipelineMode::kThreaded);
  std::atomic<std::uint64_t> produced{0};
  test::Gate release_never;  // the slow stage waits on it with a bounded timeout
  auto ids = pipeline.addSource<std::uint64_t>("source", [&]() -> SourceStep<std::uint64_t> {
    return SourceStep<std::uint64_t>::of(produced.fetch_add(1));
  });
  pipeline.addSink<std::uint64_t>("stuck", ids, {16, EdgePolicy::kBackpressure},
                                  [&](std::uint64_t) { release_never.waitOpen(200ms); });
  pipeline.start();
  // Wait (bounded) until the queue is full and the source is blocked by backpressure.
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (pipeline.stats()[1].inputs[0].depth < 16 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::yield();
  }
  const auto start = std::chrono::steady_clock::now();
  const StopReport report = pipeline.stop(300ms);
  const auto elapsed = std::chrono::steady_clock::now() - start;
  EXPECT_FALSE(report.drained);
  // Deadline (300 ms) + at most one item in progress (200 ms) + scheduling slack.
  EXPECT_LT(elapsed, 2s);
  const auto stats = pipeline.stats();
  const EdgeStats edge = stats[1].inputs[0];
  EXPECT_GT(report.discarded, 0u);
  EXPECT_EQ(edge.pushed, edge.delivered + edge.discarded + edge.depth);
  EXPECT_EQ(edge.depth, 0u);
  EXPECT_EQ(stats[1].processed, edge.delivered);
}

TEST_F(PipelineTest, StopWithinDeadlineDrainsEverything) {
  Pipeline pipeline(PipelineMode::kThreaded);
  std::uint64_t next = 0;
  std::atomic<std::uint64_t> sunk{0};
  auto ids = pipeline.addSource<std::uint64_t>("source", [&]() -> SourceStep<std::uint64_t> {
    return SourceStep<std::uint64_t>::of(next++);
  });
  auto doubled = pipeline.addStage<std::uint64_t, std::uint64_t>(
      "double", ids, {8, EdgePolicy::kBackpressure},
      [](std::uint64_t v) -> std::optional<std::uint64_t> { return 2 * v; });
  pipeline.addSink<std::uint64_t>("sink", doubled, {8, EdgePolicy::kBackpressure},
                                  [&](std::uint64_t) { sunk.fetch_add(1); });
  pipeline.start();
  while (sunk.load() < 1000) std::this_thread::yield();
  const StopReport report = pipeline.stop(10s);
  EXPECT_TRUE(report.drained);
  EXPECT_EQ(report.discarded, 0u);
  const auto stats = pipeline.stats();
  // Everything the source produced went all the way through.
  EXPECT_EQ(stats[0].processed, sunk.load());
  EXPECT_EQ(stats[2].processed, sunk.load());
}

TEST_F(PipelineTest, ThrowingStageCountsErrorsAndKeepsRunning) {
  Pipeline pipeline(PipelineMode::kThreaded);
  std::uint64_t next = 0;
  std::vector<std::uint64_t> sunk;
  auto ids = pipeline.addSource<std::uint64_t>("source", [&]() -> SourceStep<std::uint64_t> {
    if (next == 100) return SourceStep<std::uint64_t>::end();
    return SourceStep<std::uint64_t>::of(next++);
  });
  auto checked = pipeline.addStage<std::uint64_t, std::uint64_t>(
      "check", ids, {4, EdgePolicy::kBackpressure},
      [](std::uint64_t v) -> std::optional<std::uint64_t> {
        if (v % 10 == 3) throw std::runtime_error("bad item " + std::to_string(v));
        if (v % 10 == 5) return std::nullopt;  // filtered, not an error
        return v;
      });
  pipeline.addSink<std::uint64_t>("sink", checked, {4, EdgePolicy::kBackpressure},
                                  [&](std::uint64_t v) { sunk.push_back(v); });
  pipeline.start();
  ASSERT_TRUE(pipeline.waitUntilFinished(std::chrono::steady_clock::now() + 30s));
  pipeline.stop(1s);
  const auto stats = pipeline.stats();
  EXPECT_EQ(stats[1].errors, 10u);
  EXPECT_EQ(stats[1].processed, 100u);
  EXPECT_EQ(stats[1].emitted, 80u);
  EXPECT_EQ(sunk.size(), 80u);
}

// A packet that may be a heartbeat (no payload), as the daemon's packets are.
struct MaybeWork {
  std::optional<std::uint64_t> value;
  bool isHeartbeat() const { return !value.has_value(); }
};

TEST_F(PipelineTest, HeartbeatsPassThroughButAreNeitherCountedNorTimedAsWork) {
  // A source that mostly idles sends heartbeats; the stage's count and time per item must describe
  // the real items only (a tracking stage once reported p50 0.002 ms over heartbeats while three
  // frames were tracked).
  Pipeline pipeline(PipelineMode::kThreaded);
  int step = 0;
  std::atomic<int> heartbeats_seen{0};
  auto items = pipeline.addSource<MaybeWork>("source", [&]() -> SourceStep<MaybeWork> {
    if (step == 40) return SourceStep<MaybeWork>::end();
    const bool work = step++ % 4 == 0;
    return SourceStep<MaybeWork>::of(work ? MaybeWork{static_cast<std::uint64_t>(step)}
                                          : MaybeWork{});
  });
  auto worked =
      pipeline.addStage<MaybeWork, MaybeWork>("work", items, {64, EdgePolicy::kBackpressure},
                                              [](MaybeWork item) -> std::optional<MaybeWork> {
                                                // Simulated work of 2 ms per real item (not
                                                // synchronisation).
                                                if (!item.isHeartbeat())
                                                  std::this_thread::sleep_for(2ms);
                                                return item;
                                              });
  pipeline.addSink<MaybeWork>("sink", worked, {64, EdgePolicy::kBackpressure}, [&](MaybeWork item) {
    if (item.isHeartbeat()) heartbeats_seen.fetch_add(1);
  });
  pipeline.start();
  ASSERT_TRUE(pipeline.waitUntilFinished(std::chrono::steady_clock::now() + 30s));
  pipeline.stop(1s);
  const auto stats = pipeline.stats();
  EXPECT_EQ(heartbeats_seen.load(), 30) << "heartbeats still reach every stage";
  for (const auto& stage : stats) {
    EXPECT_EQ(stage.processed, 10u) << stage.name;
    EXPECT_EQ(stage.heartbeats, 30u) << stage.name;
  }
  EXPECT_EQ(stats[1].emitted, 40u);
  EXPECT_GE(stats[1].latency.p50_ms, 1.5) << "the median is over real items only";
}

TEST_F(PipelineTest, FanOutFeedsEveryConsumer) {
  Pipeline pipeline(PipelineMode::kThreaded);
  std::uint64_t next = 0;
  std::uint64_t sum_a = 0;
  std::uint64_t sum_b = 0;
  auto ids = pipeline.addSource<std::uint64_t>("source", [&]() -> SourceStep<std::uint64_t> {
    if (next == 1000) return SourceStep<std::uint64_t>::end();
    return SourceStep<std::uint64_t>::of(next++);
  });
  pipeline.addSink<std::uint64_t>("a", ids, {4, EdgePolicy::kBackpressure},
                                  [&](std::uint64_t v) { sum_a += v; });
  pipeline.addSink<std::uint64_t>("b", ids, {4, EdgePolicy::kBackpressure},
                                  [&](std::uint64_t v) { sum_b += v; });
  pipeline.start();
  ASSERT_TRUE(pipeline.waitUntilFinished(std::chrono::steady_clock::now() + 30s));
  pipeline.stop(1s);
  EXPECT_EQ(sum_a, 999u * 1000u / 2u);
  EXPECT_EQ(sum_b, sum_a);
}

TEST_F(PipelineTest, GraphCannotChangeAfterStart) {
  Pipeline pipeline(PipelineMode::kThreaded);
  auto ids = pipeline.addSource<int>("source", [] { return SourceStep<int>::end(); });
  pipeline.start();
  EXPECT_THROW(pipeline.addSink<int>("late", ids, {}, [](int) {}), std::logic_error);
  pipeline.stop(1s);
}

TEST_F(PipelineTest, DestructorStopsARunningPipeline) {
  std::atomic<std::uint64_t> sunk{0};
  {
    Pipeline pipeline(PipelineMode::kThreaded);
    auto ids = pipeline.addSource<int>("source", [] { return SourceStep<int>::of(1); });
    pipeline.addSink<int>("sink", ids, {4, EdgePolicy::kDropOldest},
                          [&](int) { sunk.fetch_add(1); });
    pipeline.start();
    while (sunk.load() < 10) std::this_thread::yield();
  }
  SUCCEED();
}

}  // namespace
}  // namespace slamd
