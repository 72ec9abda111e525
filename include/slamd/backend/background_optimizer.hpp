#pragma once
// BackgroundOptimizer: runs whole-graph optimisations on a thread of its own, so that a loop
// closed far from its start never holds up the keyframes behind it. The back end (the only
// client) hands over a copy of its graph (Backend::takeFullOptimizationJob), goes on with its
// keyframes, and merges the optimised copy when it comes back (Backend::finishFullOptimization).
//
// Usage (from the one thread that owns the Backend):
//   BackgroundOptimizer optimizer;
//   on every call of the back-end step:
//     if (auto done = optimizer.poll()) backend.finishFullOptimization(*done);
//     if (!optimizer.busy())
//       if (auto job = backend.takeFullOptimizationJob()) optimizer.submit(std::move(*job));
//   at the end: if (auto done = optimizer.wait()) backend.finishFullOptimization(*done);
//
// One job at a time: the job and its result pass through a mailbox of capacity one, owned by
// whichever side holds it. The thread starts with the first job, so it is created by (and
// inherits the niceness of) the thread that submits, not the one that built the object. The
// destructor waits for a running optimisation to finish (PoseGraph::optimize cannot be
// interrupted) and joins.

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>
#include <thread>

#include "slamd/backend/pose_graph.hpp"

namespace slamd {

/// A whole-graph optimisation: a copy of the graph, optimised in place by whoever runs it.
struct FullOptimizationJob {
  PoseGraph graph;
  PoseGraphOptions options;
  /// The newest node when the copy was taken: keyframes added since are moved with it.
  std::int64_t newest_id = -1;
  /// Filled in by run().
  PoseGraphResult result;
  bool done = false;

  /// Optimises the copy (on the calling thread).
  void run();
};

/// Moves the live graph to a finished job's optimised copy: nodes in the copy take their
/// optimised poses, nodes added to `live` since the copy was taken move rigidly with the copy's
/// newest node (they hang off it by odometry). Edges are not touched. False, and nothing moves,
/// when the optimisation failed or the copy's newest node is no longer in `live`.
bool mergeOptimizedCopy(const FullOptimizationJob& job, PoseGraph& live);

class BackgroundOptimizer {
 public:
  BackgroundOptimizer() = default;
  ~BackgroundOptimizer();
  BackgroundOptimizer(const BackgroundOptimizer&) = delete;
  BackgroundOptimizer& operator=(const BackgroundOptimizer&) = delete;

  /// Starts the job on the worker thread. False (and nothing happens) while another job is
  /// running or its result has not been collected.
  bool submit(FullOptimizationJob job);
  /// The finished job, once; nullopt while it runs or when there is none.
  std::optional<FullOptimizationJob> poll();
  /// Waits for the job in flight, if any, and returns it.
  std::optional<FullOptimizationJob> wait();
  /// A job was submitted and not yet collected.
  bool busy() const;

 private:
  void loop();

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::optional<FullOptimizationJob> job_;  ///< guarded by mutex_ (submitted, running or done)
  bool running_ = false;                    ///< guarded by mutex_: the worker holds the job
  bool stop_ = false;                       ///< guarded by mutex_
  std::thread worker_;                      ///< started by the first submit()
};

}  // namespace slamd
