#include "slamd/pipeline/pipeline.hpp"

#include <pthread.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "slamd/common/log.hpp"

namespace slamd {

const char* edgePolicyName(EdgePolicy policy) {
  switch (policy) {
    case EdgePolicy::kBackpressure:
      return "backpressure";
    case EdgePolicy::kDropOldest:
      return "drop-oldest";
    case EdgePolicy::kDrainToNewest:
      return "drain-to-newest";
    case EdgePolicy::kGrowing:
      return "growing";
  }
  return "?";
}

namespace pipeline_detail {

void NodeBase::reportError(const char* what) {
  const std::uint64_t count = errors_.fetch_add(1, std::memory_order_relaxed) + 1;
  // The first errors are logged in full, then one line per 100 so a stream of bad input cannot
  // flood the log; every error is counted either way.
  if (count <= 10 || count % 100 == 0) {
    SLAMD_LOG_WARN(name_.c_str()) << "item dropped after error #" << count << ": " << what;
  }
}

}  // namespace pipeline_detail

Pipeline::Pipeline(PipelineMode mode) : mode_(mode) {}

Pipeline::~Pipeline() {
  if (started_ && !joined_) stop(std::chrono::seconds(2));
}

void Pipeline::checkBuilding() const {
  if (started_) throw std::logic_error("the pipeline graph cannot change after start()");
}

void Pipeline::start() {
  if (started_) throw std::logic_error("Pipeline::start() called twice");
  started_ = true;
  if (mode_ == PipelineMode::kSequential) return;
  threads_.reserve(nodes_.size());
  for (auto& node : nodes_) {
    pipeline_detail::NodeBase* raw = node.get();
    threads_.emplace_back([raw] {
      // Named after the stage ("slamd:tracking", cut to Linux's 15 characters) so that top -H,
      // perf and gdb show which stage a thread is.
      const std::string thread_name = ("slamd:" + raw->name()).substr(0, 15);
      pthread_setname_np(pthread_self(), thread_name.c_str());
      if (raw->nice() != 0) {
        // Linux applies setpriority(PRIO_PROCESS, tid) to one thread.
        const auto tid = static_cast<id_t>(syscall(SYS_gettid));
        if (setpriority(PRIO_PROCESS, tid, raw->nice()) != 0) {
          SLAMD_LOG_WARN("pipeline")
              << "cannot set niceness " << raw->nice() << " of stage '" << raw->name() << "'";
        }
      }
      raw->run();
    });
  }
}

void Pipeline::run() {
  if (mode_ != PipelineMode::kSequential) {
    throw std::logic_error("Pipeline::run() is for sequential mode; use start() and stop()");
  }
  if (!started_) start();
  // Round-robin over the sources so several sources interleave as they would when threaded.
  bool any_source_active = true;
  while (any_source_active) {
    any_source_active = false;
    for (auto& node : nodes_) {
      if (!node->finished() && node->stepSource()) any_source_active = true;
    }
  }
  for (auto& node : nodes_) {
    if (!node->finished()) node->finishInline();
  }
  joined_ = true;
}

bool Pipeline::waitUntilFinished(std::chrono::steady_clock::time_point deadline) {
  auto all_finished = [&] {
    for (const auto& node : nodes_) {
      if (!node->finished()) return false;
    }
    return true;
  };
  while (true) {
    const auto seen = control_.finished_signal.epoch();
    if (all_finished()) return true;
    if (std::chrono::steady_clock::now() >= deadline) return false;
    control_.finished_signal.waitFor(seen, deadline);
  }
}

StopReport Pipeline::stop(std::chrono::milliseconds drain_deadline) {
  StopReport report;
  const std::int64_t start_ns = steadyNowNs();
  // 1. Sources stop first; end of stream then flows through every stage.
  control_.stop_requested.store(true, std::memory_order_release);
  if (!started_ || joined_ || mode_ == PipelineMode::kSequential) {
    joined_ = joined_ || started_;
    return report;
  }
  // 2. Stages drain what is queued, within the deadline.
  if (!waitUntilFinished(std::chrono::steady_clock::now() + drain_deadline)) {
    // 3. Too slow: abort. Each stage finishes its current item, counts the rest as discarded.
    report.drained = false;
    control_.abort.store(true, std::memory_order_release);
    for (auto& node : nodes_) node->wakeInputs();
    SLAMD_LOG_WARN("pipeline") << "drain deadline of " << drain_deadline.count()
                               << " ms passed; discarding queued items";
  }
  // 4. Join in graph order (sources first), one log line each.
  joinAll();
  for (const auto& node : nodes_) {
    for (const auto& edge : node->stats().inputs) report.discarded += edge.discarded;
  }
  report.elapsed_ms = static_cast<double>(steadyNowNs() - start_ns) * 1e-6;
  return report;
}

void Pipeline::joinAll() {
  for (std::size_t i = 0; i < threads_.size(); ++i) {
    if (threads_[i].joinable()) threads_[i].join();
    SLAMD_LOG_DEBUG("pipeline") << "stage '" << nodes_[i]->name() << "' stopped";
  }
  joined_ = true;
}

void Pipeline::setStageNice(const std::string& name, int nice) {
  checkBuilding();
  for (auto& node : nodes_) {
    if (node->name() == name) {
      node->setNice(nice);
      return;
    }
  }
  throw std::invalid_argument("no stage named '" + name + "'");
}

std::vector<StageStats> Pipeline::stats() const {
  std::vector<StageStats> out;
  out.reserve(nodes_.size());
  for (const auto& node : nodes_) out.push_back(node->stats());
  return out;
}

}  // namespace slamd
