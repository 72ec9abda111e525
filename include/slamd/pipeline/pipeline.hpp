#pragma once
// Pipeline: runs a graph of stages connected by bounded lock-free queues.
//
// A stage is an algorithm `std::optional<Out> process(In)` with no threads inside (nullopt means
// "nothing to pass on for this input"). A source produces items; a sink consumes them. The
// pipeline owns the threads (one per node, started by start(), never by a constructor) and the
// queues (one per edge, single producer / single consumer).
//
//   Pipeline pipeline(PipelineMode::kThreaded);
//   auto frames = pipeline.addSource<FramePtr>("capture", [&] { return source.next(); });
//   auto poses  = pipeline.addStage<FramePtr, Pose>("tracking", frames,
//                     {4, EdgePolicy::kDropOldest}, [&](FramePtr f) { return vo.process(f); });
//   pipeline.addSink<Pose>("publish", poses, {64, EdgePolicy::kBackpressure},
//                     [&](Pose p) { publisher.publish(p); });
//   pipeline.start();
//   pipeline.waitUntilFinished(deadline);   // the source ended and everything drained
//   pipeline.stop(std::chrono::seconds(2)); // or: stop the source now, drain within 2 s
//
// Edge policies (chosen per edge, by the consumer's connection):
// - kBackpressure: the producer waits while the queue is full; nothing is ever dropped.
// - kDropOldest: the producer never waits; a full queue evicts its oldest item (live sources).
// - kDrainToNewest: the producer never waits (oldest evicted when full) and the consumer takes
//   only the newest waiting item, dropping the older ones (a mapper that skips to the newest).
// Every drop is counted exactly: pushed = processed + heartbeats + dropped + discarded at
// shutdown.
//
// Heartbeats: an item type may mark items that carry no work and only wake the stages (a packet
// without a frame) by declaring `bool isHeartbeat() const`. They flow like any item, but are
// counted apart and not timed, so a stage's processed count, rate and time per item describe
// real work only.
//
// End of stream: when a source returns SourceStep::end() (or stop() is called) it closes its
// output queues; each stage processes everything left in its input, then closes its own outputs.
//
// Shutdown (stop): the source stops first, then each stage drains in order; if draining takes
// longer than the deadline the pipeline aborts: stages finish their current item, discard what
// is queued (counted) and exit. Threads are joined in graph order with a log line each.
//
// Sequential mode runs the same graph on the calling thread (run()): each item is pushed through
// the whole graph before the source is asked for the next, so outputs are deterministic and equal
// to the threaded mode's whenever no edge drops.
//
// Ownership: the Pipeline object belongs to the thread that built it; start/stop/wait/stats are
// called from that thread (stats() may also be called from any thread while running).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "slamd/common/latency_histogram.hpp"
#include "slamd/common/time.hpp"
#include "slamd/pipeline/drop_oldest_queue.hpp"
#include "slamd/pipeline/growing_spsc_queue.hpp"
#include "slamd/pipeline/spsc_queue.hpp"
#include "slamd/pipeline/wake_signal.hpp"

namespace slamd {

/// How an edge behaves when its consumer falls behind:
/// - kBackpressure: the producer waits for room (datasets: nothing lost, runs repeatable);
/// - kDropOldest: the oldest waiting item is dropped and counted (live frames);
/// - kDrainToNewest: the consumer takes the newest item and skips the rest (mapping);
/// - kGrowing: nothing is dropped and the producer never waits; the queue grows by a segment of
///   `capacity` items at a time (a consumer that needs every item but must not hold up the
///   latency-critical path; keep its items small).
enum class EdgePolicy { kBackpressure, kDropOldest, kDrainToNewest, kGrowing };
enum class PipelineMode { kThreaded, kSequential };

const char* edgePolicyName(EdgePolicy policy);

struct EdgeOptions {
  std::size_t capacity = 16;
  EdgePolicy policy = EdgePolicy::kBackpressure;
};

/// What a source function returns: an item, nothing yet (call again), or end of stream.
template <typename T>
struct SourceStep {
  enum class Kind { kItem, kIdle, kEnd };
  Kind kind = Kind::kIdle;
  std::optional<T> item;

  static SourceStep of(T value) { return SourceStep{Kind::kItem, std::move(value)}; }
  static SourceStep idle() { return SourceStep{Kind::kIdle, std::nullopt}; }
  static SourceStep end() { return SourceStep{Kind::kEnd, std::nullopt}; }
};

/// Counters of one edge (a node's input queue).
struct EdgeStats {
  std::string policy;
  std::size_t capacity = 0;
  std::size_t depth = 0;        ///< items waiting now (approximate while running)
  std::uint64_t pushed = 0;     ///< items offered by the producer
  std::uint64_t delivered = 0;  ///< items handed to the consumer
  std::uint64_t dropped = 0;    ///< items dropped by the policy
  std::uint64_t discarded = 0;  ///< items thrown away by an aborted shutdown
};

/// Counters of one node.
struct StageStats {
  std::string name;
  std::uint64_t processed = 0;   ///< inputs processed (sources: items produced), not heartbeats
  std::uint64_t heartbeats = 0;  ///< heartbeat items passed on (see above)
  std::uint64_t emitted = 0;     ///< outputs passed on
  std::uint64_t errors = 0;      ///< process() calls that threw (item dropped, pipeline continues)
  std::vector<std::uint64_t> latency_buckets;  ///< LatencyHistogram::snapshot() of process()
  LatencySummary latency;
  /// The node thread's CPU time per item: what an item costs, without the time spent waiting
  /// for a core (on a loaded machine, and for a niced stage, far below the wall time).
  LatencySummary cpu;
  std::vector<EdgeStats> inputs;  ///< empty for sources
  bool finished = false;
};

namespace pipeline_detail {

template <typename T, typename = void>
struct HasIsHeartbeat : std::false_type {};
template <typename T>
struct HasIsHeartbeat<T, std::void_t<decltype(std::declval<const T&>().isHeartbeat())>>
    : std::true_type {};

template <typename T>
bool isHeartbeatItem(const T& item) {
  if constexpr (HasIsHeartbeat<T>::value) {
    return item.isHeartbeat();
  } else {
    (void)item;
    return false;
  }
}

/// Shared run state of one pipeline, read by every node.
struct RunControl {
  std::atomic<bool> stop_requested{false};  ///< sources stop producing
  std::atomic<bool> abort{false};           ///< stages stop draining
  WakeSignal finished_signal;               ///< notified whenever a node finishes
};

/// Wait granularity: a blocked thread re-checks stop/abort at least this often, so a notify
/// missed by design (abort is flagged without touching every signal) costs at most this long.
constexpr std::chrono::milliseconds kWaitSlice{50};

class NodeBase;

/// A queue between one producer node and one consumer node.
template <typename T>
class Edge {
 public:
  Edge(const EdgeOptions& options, RunControl* control) : options_(options), control_(control) {
    if (options.capacity == 0) throw std::invalid_argument("edge capacity must be at least 1");
    if (options.policy == EdgePolicy::kBackpressure) {
      blocking_queue_ = std::make_unique<SpscQueue<T>>(options.capacity);
    } else if (options.policy == EdgePolicy::kGrowing) {
      growing_queue_ = std::make_unique<GrowingSpscQueue<T>>(options.capacity);
    } else {
      evicting_queue_ = std::make_unique<DropOldestQueue<T>>(options.capacity);
    }
  }

  /// Build time: a function applied to each item on the producer's thread before it waits in
  /// this queue (to drop what this consumer does not need).
  void setOnEnqueue(std::function<void(T&)> on_enqueue) { on_enqueue_ = std::move(on_enqueue); }

  /// Producer side. Returns false only when an abort made a backpressure push give up (the item
  /// is then counted as discarded).
  bool push(T item, const std::function<void()>& run_consumer_inline) {
    pushed_.fetch_add(1, std::memory_order_relaxed);
    if (on_enqueue_) on_enqueue_(item);
    if (growing_queue_ || evicting_queue_) {
      if (growing_queue_) {
        growing_queue_->push(std::move(item));
      } else {
        evicting_queue_->push(std::move(item));
      }
      data_signal_.notify();
      if (run_consumer_inline) run_consumer_inline();
      return true;
    }
    while (true) {
      const auto seen = space_signal_.epoch();
      if (blocking_queue_->tryPush(std::move(item))) {  // moves only on success
        data_signal_.notify();
        if (run_consumer_inline) run_consumer_inline();
        return true;
      }
      if (run_consumer_inline) {  // sequential mode: make room by running the consumer now
        run_consumer_inline();
        continue;
      }
      if (control_->abort.load(std::memory_order_acquire)) {
        discarded_.fetch_add(1, std::memory_order_relaxed);
        return false;
      }
      space_signal_.waitFor(seen, std::chrono::steady_clock::now() + kWaitSlice);
    }
  }

  /// Producer side: end of stream.
  void close() {
    if (blocking_queue_)
      blocking_queue_->close();
    else if (growing_queue_)
      growing_queue_->close();
    else
      evicting_queue_->close();
    data_signal_.notify();
  }

  /// Consumer side, non-blocking: the next item by policy, or nullopt.
  std::optional<T> tryPop() {
    std::optional<T> item;
    if (blocking_queue_) {
      item = blocking_queue_->tryPop();
      if (item) space_signal_.notify();
    } else if (growing_queue_) {
      item = growing_queue_->tryPop();
    } else {
      item = evicting_queue_->tryPop();
      if (item && options_.policy == EdgePolicy::kDrainToNewest) {
        while (auto newer = evicting_queue_->tryPop()) {
          item = std::move(newer);
          drained_to_newest_.fetch_add(1, std::memory_order_relaxed);
        }
      }
    }
    if (item) delivered_.fetch_add(1, std::memory_order_relaxed);
    return item;
  }

  /// Consumer side: true once closed and empty.
  bool drained() {
    if (blocking_queue_) return blocking_queue_->drained();
    return growing_queue_ ? growing_queue_->drained() : evicting_queue_->drained();
  }

  /// Consumer side, blocking: the next item, or nullopt at end of stream or abort.
  std::optional<T> popWait() {
    while (true) {
      const auto seen = data_signal_.epoch();
      if (control_->abort.load(std::memory_order_acquire)) return std::nullopt;
      if (auto item = tryPop()) return item;
      if (drained()) {
        tryPop();  // lets a drop-oldest queue account for stale items after close
        return std::nullopt;
      }
      data_signal_.waitFor(seen, std::chrono::steady_clock::now() + kWaitSlice);
    }
  }

  /// Consumer side, after it stopped: counts whatever is left as discarded.
  void discardRemaining() {
    while (true) {
      std::optional<T> item = blocking_queue_  ? blocking_queue_->tryPop()
                              : growing_queue_ ? growing_queue_->tryPop()
                                               : evicting_queue_->tryPop();
      if (!item) break;
      discarded_.fetch_add(1, std::memory_order_relaxed);
    }
    space_signal_.notify();
  }

  void wakeAll() {
    data_signal_.notify();
    space_signal_.notify();
  }

  EdgeStats stats() const {
    EdgeStats s;
    s.policy = edgePolicyName(options_.policy);
    s.capacity = options_.capacity;
    s.depth = blocking_queue_  ? blocking_queue_->sizeApprox()
              : growing_queue_ ? growing_queue_->sizeApprox()
                               : evicting_queue_->sizeApprox();
    s.pushed = pushed_.load(std::memory_order_relaxed);
    s.delivered = delivered_.load(std::memory_order_relaxed);
    s.dropped = drained_to_newest_.load(std::memory_order_relaxed) +
                (evicting_queue_ ? evicting_queue_->dropped() : 0);
    s.discarded = discarded_.load(std::memory_order_relaxed);
    return s;
  }

 private:
  EdgeOptions options_;
  RunControl* control_;
  std::unique_ptr<SpscQueue<T>> blocking_queue_;        // kBackpressure
  std::unique_ptr<DropOldestQueue<T>> evicting_queue_;  // kDropOldest, kDrainToNewest
  std::unique_ptr<GrowingSpscQueue<T>> growing_queue_;  // kGrowing
  std::function<void(T&)> on_enqueue_;
  WakeSignal data_signal_;   // producer -> consumer: an item or end of stream arrived
  WakeSignal space_signal_;  // consumer -> producer: a slot became free
  std::atomic<std::uint64_t> pushed_{0};
  std::atomic<std::uint64_t> delivered_{0};
  std::atomic<std::uint64_t> drained_to_newest_{0};
  std::atomic<std::uint64_t> discarded_{0};
};

/// Type-erased node as the Pipeline sees it.
class NodeBase {
 public:
  explicit NodeBase(std::string name, RunControl* control)
      : name_(std::move(name)), control_(control) {}
  virtual ~NodeBase() = default;

  const std::string& name() const { return name_; }
  /// Thread body (threaded mode): runs until end of stream or abort, then closes outputs.
  virtual void run() = 0;
  /// Sequential mode, sources only: produce one item and push it through the graph.
  /// Returns false at end of stream.
  virtual bool stepSource() { return false; }
  /// Sequential mode: process everything waiting in the input.
  virtual void drainInline() {}
  /// Sequential mode: close outputs after the input ended.
  virtual void finishInline() = 0;
  virtual StageStats stats() const = 0;
  virtual void wakeInputs() {}
  virtual void discardInputs() {}

  bool finished() const { return finished_.load(std::memory_order_acquire); }
  /// Scheduling niceness of this node's thread (0 = the process's; higher = yields CPU to the
  /// others), applied when its thread starts.
  void setNice(int nice) { nice_ = nice; }
  int nice() const { return nice_; }

 protected:
  void markFinished() {
    finished_.store(true, std::memory_order_release);
    control_->finished_signal.notify();
  }
  StageStats baseStats() const {
    StageStats s;
    s.name = name_;
    s.processed = processed_.load(std::memory_order_relaxed);
    s.heartbeats = heartbeats_.load(std::memory_order_relaxed);
    s.emitted = emitted_.load(std::memory_order_relaxed);
    s.errors = errors_.load(std::memory_order_relaxed);
    s.latency_buckets = latency_.snapshot();
    s.latency = latency_.summary();
    s.cpu = cpu_.summary();
    s.finished = finished();
    return s;
  }
  void reportError(const char* what);

  std::string name_;
  RunControl* control_;
  int nice_ = 0;
  std::atomic<bool> finished_{false};
  /// When an item's handling started, by the wall clock and the thread's CPU clock.
  struct ItemStart {
    std::int64_t wall_ns = steadyNowNs();
    std::int64_t cpu_ns = threadCpuNowNs();
  };
  /// Counts one item handled since `start`: timed and counted as processed unless it was a
  /// heartbeat.
  void countItem(bool heartbeat, const ItemStart& start) {
    if (heartbeat) {
      heartbeats_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    latency_.recordNs(steadyNowNs() - start.wall_ns);
    cpu_.recordNs(threadCpuNowNs() - start.cpu_ns);
    processed_.fetch_add(1, std::memory_order_relaxed);
  }

  std::atomic<std::uint64_t> processed_{0};
  std::atomic<std::uint64_t> heartbeats_{0};
  std::atomic<std::uint64_t> emitted_{0};
  std::atomic<std::uint64_t> errors_{0};
  LatencyHistogram latency_;
  LatencyHistogram cpu_;
};

/// The producing end of a node: fans each output item out to every connected edge.
template <typename T>
class OutputPort {
 public:
  void connect(std::shared_ptr<Edge<T>> edge, NodeBase* consumer) {
    if constexpr (!std::is_copy_constructible_v<T>) {
      if (!edges_.empty()) {
        throw std::logic_error("a move-only output cannot feed more than one stage");
      }
    }
    edges_.push_back(std::move(edge));
    consumers_.push_back(consumer);
  }

  /// Pushes to every edge; in sequential mode runs each consumer right after its push.
  /// Returns the number of edges that accepted the item.
  std::size_t emit(T item, bool sequential) {
    std::size_t accepted = 0;
    for (std::size_t i = 0; i < edges_.size(); ++i) {
      std::function<void()> inline_consumer;
      if (sequential) {
        NodeBase* consumer = consumers_[i];
        inline_consumer = [consumer] { consumer->drainInline(); };
      }
      const bool last = i + 1 == edges_.size();
      bool ok;
      if constexpr (std::is_copy_constructible_v<T>) {
        ok = last ? edges_[i]->push(std::move(item), inline_consumer)
                  : edges_[i]->push(T(item), inline_consumer);
      } else {
        ok = edges_[i]->push(std::move(item), inline_consumer);
      }
      if (ok) ++accepted;
    }
    return accepted;
  }

  void close() {
    for (auto& edge : edges_) edge->close();
  }

  std::vector<NodeBase*> consumers() const { return consumers_; }

 private:
  std::vector<std::shared_ptr<Edge<T>>> edges_;
  std::vector<NodeBase*> consumers_;
};

template <typename T>
class SourceNode final : public NodeBase {
 public:
  using Function = std::function<SourceStep<T>()>;
  SourceNode(std::string name, RunControl* control, Function fn)
      : NodeBase(std::move(name), control), fn_(std::move(fn)) {}

  OutputPort<T>& output() { return output_; }

  void run() override {
    while (!control_->stop_requested.load(std::memory_order_acquire)) {
      if (!stepOnce(false)) break;
    }
    output_.close();
    markFinished();
  }

  bool stepSource() override {
    if (control_->stop_requested.load(std::memory_order_acquire) || !stepOnce(true)) {
      output_.close();
      markFinished();
      return false;
    }
    return true;
  }

  void finishInline() override {
    output_.close();
    markFinished();
  }

  StageStats stats() const override { return baseStats(); }

 private:
  // Returns false at end of stream.
  bool stepOnce(bool sequential) {
    SourceStep<T> step;
    const ItemStart start;
    try {
      step = fn_();
    } catch (const std::exception& e) {
      reportError(e.what());
      return true;  // a failing read is counted; the source decides when it has ended
    }
    if (step.kind == SourceStep<T>::Kind::kEnd) return false;
    if (step.kind == SourceStep<T>::Kind::kItem && step.item) {
      countItem(isHeartbeatItem(*step.item), start);
      if (output_.emit(std::move(*step.item), sequential) > 0) {
        emitted_.fetch_add(1, std::memory_order_relaxed);
      }
    }
    return true;
  }

  Function fn_;
  OutputPort<T> output_;
};

/// A stage (Out = output type) or a sink (Out = void).
template <typename In, typename Out>
class StageNode final : public NodeBase {
 public:
  using Function = std::conditional_t<std::is_void_v<Out>, std::function<void(In)>,
                                      std::function<std::optional<Out>(In)>>;

  StageNode(std::string name, RunControl* control, std::shared_ptr<Edge<In>> input, Function fn)
      : NodeBase(std::move(name), control), input_(std::move(input)), fn_(std::move(fn)) {}

  template <typename O = Out, typename = std::enable_if_t<!std::is_void_v<O>>>
  OutputPort<O>& output() {
    return output_;
  }

  void run() override {
    while (auto item = input_->popWait()) processOne(std::move(*item), false);
    // Aborted: what is still queued is counted, not processed.
    if (control_->abort.load(std::memory_order_acquire)) input_->discardRemaining();
    closeOutputs();
    markFinished();
  }

  void drainInline() override {
    while (auto item = input_->tryPop()) processOne(std::move(*item), true);
  }

  void finishInline() override {
    drainInline();
    input_->drained();
    closeOutputs();
    markFinished();
  }

  StageStats stats() const override {
    StageStats s = baseStats();
    s.inputs.push_back(input_->stats());
    return s;
  }

  void wakeInputs() override { input_->wakeAll(); }
  void discardInputs() override { input_->discardRemaining(); }

 private:
  void processOne(In item, bool sequential) {
    const bool heartbeat = isHeartbeatItem(item);
    const ItemStart start;
    try {
      if constexpr (std::is_void_v<Out>) {
        fn_(std::move(item));
        countItem(heartbeat, start);
      } else {
        std::optional<Out> result = fn_(std::move(item));
        countItem(heartbeat, start);
        if (result && output_.emit(std::move(*result), sequential) > 0) {
          emitted_.fetch_add(1, std::memory_order_relaxed);
        }
      }
    } catch (const std::exception& e) {
      (heartbeat ? heartbeats_ : processed_).fetch_add(1, std::memory_order_relaxed);
      reportError(e.what());
    }
  }

  void closeOutputs() {
    if constexpr (!std::is_void_v<Out>) output_.close();
  }

  struct NoOutput {};
  std::shared_ptr<Edge<In>> input_;
  Function fn_;
  std::conditional_t<std::is_void_v<Out>, NoOutput,
                     OutputPort<std::conditional_t<std::is_void_v<Out>, int, Out>>>
      output_;
};

}  // namespace pipeline_detail

/// A typed handle to a node's output, used to connect consumers.
template <typename T>
class Outlet {
 public:
  Outlet() = default;

 private:
  friend class Pipeline;
  Outlet(pipeline_detail::OutputPort<T>* port, const void* owner) : port_(port), owner_(owner) {}
  pipeline_detail::OutputPort<T>* port_ = nullptr;
  const void* owner_ = nullptr;
};

/// Outcome of stop().
struct StopReport {
  bool drained = true;          ///< every queued item was processed before the deadline
  std::uint64_t discarded = 0;  ///< items thrown away because the deadline passed
  double elapsed_ms = 0.0;
};

class Pipeline {
 public:
  explicit Pipeline(PipelineMode mode = PipelineMode::kThreaded);
  ~Pipeline();

  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  template <typename T>
  Outlet<T> addSource(const std::string& name,
                      typename pipeline_detail::SourceNode<T>::Function fn) {
    checkBuilding();
    auto node = std::make_unique<pipeline_detail::SourceNode<T>>(name, &control_, std::move(fn));
    Outlet<T> outlet(&node->output(), this);
    nodes_.push_back(std::move(node));
    return outlet;
  }

  template <typename In, typename Out>
  Outlet<Out> addStage(const std::string& name, Outlet<In> input, const EdgeOptions& edge,
                       typename pipeline_detail::StageNode<In, Out>::Function fn) {
    auto* node = addConsumer<In, Out>(name, input, edge, std::move(fn));
    return Outlet<Out>(&node->output(), this);
  }

  /// `on_enqueue`, when given, is applied to each item on the producer's thread before it waits
  /// in this sink's queue: a sink that needs less of an item than its other consumers (the back
  /// end: no images of frames that are not keyframes) keeps its backlog small.
  template <typename In>
  void addSink(const std::string& name, Outlet<In> input, const EdgeOptions& edge,
               std::function<void(In)> fn, std::function<void(In&)> on_enqueue = {}) {
    addConsumer<In, void>(name, input, edge, std::move(fn), std::move(on_enqueue));
  }

  /// Threaded mode: starts one thread per node. Sequential mode: does nothing (call run()).
  void start();

  /// Sequential mode: runs the whole graph on this thread until the sources end.
  void run();

  /// Waits until every node finished (sources ended and everything drained). False on timeout.
  bool waitUntilFinished(std::chrono::steady_clock::time_point deadline);

  /// Stops the sources, lets the stages drain until the deadline, then aborts; joins all threads
  /// in graph order. Safe to call more than once and after the pipeline finished by itself.
  StopReport stop(std::chrono::milliseconds drain_deadline);

  /// Counters of every node in graph order (callable from any thread while running).
  std::vector<StageStats> stats() const;

  /// Lowers (nice > 0) the CPU priority of one node's thread, for stages off the latency-critical
  /// path (e.g. mapping) so they use what the critical path leaves. Call before start().
  /// Throws std::invalid_argument for an unknown name.
  void setStageNice(const std::string& name, int nice);

  bool running() const { return started_ && !joined_; }

 private:
  template <typename In, typename Out>
  pipeline_detail::StageNode<In, Out>* addConsumer(
      const std::string& name, Outlet<In> input, const EdgeOptions& edge,
      typename pipeline_detail::StageNode<In, Out>::Function fn,
      std::function<void(In&)> on_enqueue = {}) {
    checkBuilding();
    if (input.port_ == nullptr || input.owner_ != this) {
      throw std::logic_error("stage '" + name + "' is connected to an outlet of another pipeline");
    }
    auto queue = std::make_shared<pipeline_detail::Edge<In>>(edge, &control_);
    if (on_enqueue) queue->setOnEnqueue(std::move(on_enqueue));
    auto node = std::make_unique<pipeline_detail::StageNode<In, Out>>(name, &control_, queue,
                                                                      std::move(fn));
    auto* raw = node.get();
    input.port_->connect(queue, raw);
    nodes_.push_back(std::move(node));
    return raw;
  }

  void checkBuilding() const;
  void joinAll();

  PipelineMode mode_;
  pipeline_detail::RunControl control_;
  std::vector<std::unique_ptr<pipeline_detail::NodeBase>> nodes_;
  std::vector<std::thread> threads_;
  bool started_ = false;
  bool joined_ = false;
};

}  // namespace slamd
