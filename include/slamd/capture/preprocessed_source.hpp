#pragma once
// PreprocessedSource: a FrameSource decorator that runs DepthPreprocessor on every frame and
// times each step, plus the time the wrapped source spent producing the frame (reading and
// decoding, for file sources).
//
//   PreprocessedSource source(std::make_unique<TumSource>(...), DepthPreprocessorConfig::load(c));
//   source.open(); ... source.next(timeout) ...;
//   PreprocessingStats s = source.timings();   // p50/p95 per step
//
// Frames are copied shallowly with a fresh depth image, so the wrapped source's frames are never
// modified. Same threading as FrameSource: one owner thread; timings() may be read from any
// thread (the histograms are wait-free).

#include <memory>

#include "slamd/capture/depth_preprocessor.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/common/latency_histogram.hpp"

namespace slamd {

struct PreprocessingStats {
  LatencySummary source_next;  ///< wrapped source's next() for delivered frames (read + decode)
  LatencySummary range_gate;
  LatencySummary flying_pixels;
  LatencySummary bilateral;
  LatencySummary preprocess;  ///< all pre-processing steps of a frame
};

class PreprocessedSource : public FrameSource {
 public:
  PreprocessedSource(std::unique_ptr<FrameSource> inner, DepthPreprocessorConfig config);

  void open() override { inner_->open(); }
  FrameRead next(std::chrono::milliseconds timeout) override;
  void close() override { inner_->close(); }
  FrameSourceStats stats() const override { return inner_->stats(); }
  std::string description() const override;
  bool isLive() const override { return inner_->isLive(); }
  std::optional<CameraIntrinsics> intrinsics() const override { return inner_->intrinsics(); }
  std::optional<Trajectory> groundTruth() const override { return inner_->groundTruth(); }
  std::optional<Utime> upcomingUtime(std::size_t ahead) const override {
    return inner_->upcomingUtime(ahead);
  }
  bool dropUpcoming() override { return inner_->dropUpcoming(); }

  PreprocessingStats timings() const;

 private:
  std::unique_ptr<FrameSource> inner_;
  DepthPreprocessor preprocessor_;
  LatencyHistogram source_next_;
  LatencyHistogram range_gate_;
  LatencyHistogram flying_pixels_;
  LatencyHistogram bilateral_;
  LatencyHistogram preprocess_;
};

}  // namespace slamd
