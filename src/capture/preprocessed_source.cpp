#include "slamd/capture/preprocessed_source.hpp"

#include "slamd/common/time.hpp"

namespace slamd {

PreprocessedSource::PreprocessedSource(std::unique_ptr<FrameSource> inner,
                                       DepthPreprocessorConfig config)
    : inner_(std::move(inner)), preprocessor_(config) {}

FrameRead PreprocessedSource::next(std::chrono::milliseconds timeout) {
  const std::int64_t start = steadyNowNs();
  FrameRead read = inner_->next(timeout);
  if (read.status != FrameRead::Status::kFrame) return read;
  source_next_.recordNs(steadyNowNs() - start);
  if (!preprocessor_.config().anyEnabled()) return read;
  auto frame = std::make_shared<RgbdFrame>(*read.frame);
  frame->depth_m = read.frame->depth_m.clone();
  const DepthPreprocessTimings t = preprocessor_.process(frame->depth_m);
  if (preprocessor_.config().range_gate) range_gate_.recordNs(t.range_gate_ns);
  if (preprocessor_.config().flying_pixels) flying_pixels_.recordNs(t.flying_pixels_ns);
  if (preprocessor_.config().bilateral) bilateral_.recordNs(t.bilateral_ns);
  preprocess_.recordNs(t.totalNs());
  read.frame = std::move(frame);
  return read;
}

std::string PreprocessedSource::description() const {
  const DepthPreprocessorConfig& c = preprocessor_.config();
  std::string steps;
  if (c.range_gate) steps += " range-gate";
  if (c.flying_pixels) steps += " flying-pixels";
  if (c.bilateral) steps += " bilateral";
  return inner_->description() + ", pre-processing:" + (steps.empty() ? " none" : steps);
}

PreprocessingStats PreprocessedSource::timings() const {
  return {source_next_.summary(), range_gate_.summary(), flying_pixels_.summary(),
          bilateral_.summary(), preprocess_.summary()};
}

}  // namespace slamd
