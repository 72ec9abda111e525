#include "slamd/backend/background_optimizer.hpp"

#include <utility>

namespace slamd {

void FullOptimizationJob::run() {
  result = graph.optimize(options);
  done = true;
}

bool mergeOptimizedCopy(const FullOptimizationJob& job, PoseGraph& live) {
  const bool usable = job.done && (job.result.status == OptimizationStatus::kConverged ||
                                   job.result.status == OptimizationStatus::kMaxIterations);
  if (!usable || !live.hasNode(job.newest_id) || !job.graph.hasNode(job.newest_id)) return false;
  const SE3 T_correction = job.graph.pose(job.newest_id) * live.pose(job.newest_id).inverse();
  for (std::int64_t id : live.nodeIds()) {
    live.setPose(id, job.graph.hasNode(id) ? job.graph.pose(id) : T_correction * live.pose(id));
  }
  return true;
}

BackgroundOptimizer::~BackgroundOptimizer() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (worker_.joinable()) worker_.join();
}

bool BackgroundOptimizer::submit(FullOptimizationJob job) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (job_.has_value()) return false;
    job.done = false;
    job_ = std::move(job);
  }
  if (!worker_.joinable()) worker_ = std::thread([this] { loop(); });
  wake_.notify_all();
  return true;
}

std::optional<FullOptimizationJob> BackgroundOptimizer::poll() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!job_.has_value() || running_ || !job_->done) return std::nullopt;
  std::optional<FullOptimizationJob> finished = std::move(job_);
  job_.reset();
  return finished;
}

std::optional<FullOptimizationJob> BackgroundOptimizer::wait() {
  std::unique_lock<std::mutex> lock(mutex_);
  wake_.wait(lock, [this] { return !job_.has_value() || (!running_ && job_->done); });
  std::optional<FullOptimizationJob> finished = std::move(job_);
  job_.reset();
  return finished;
}

bool BackgroundOptimizer::busy() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return job_.has_value();
}

void BackgroundOptimizer::loop() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || (job_.has_value() && !job_->done); });
    if (stop_) return;
    // The worker owns the job while it runs: the mutex is released, and the other side only
    // looks at job_ again once running_ is false.
    running_ = true;
    FullOptimizationJob job = std::move(*job_);
    lock.unlock();
    job.run();
    lock.lock();
    *job_ = std::move(job);
    running_ = false;
    wake_.notify_all();
  }
}

}  // namespace slamd
