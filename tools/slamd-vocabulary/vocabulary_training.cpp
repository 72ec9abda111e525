#include "vocabulary_training.hpp"

#include <algorithm>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "slamd/synth/synthetic_source.hpp"
#include "slamd/tracking/features.hpp"
#include "slamd/tracking/tracking_config.hpp"

namespace slamd {

Vocabulary trainVocabularyOnSyntheticScene(const std::string& scene, int branching, int depth,
                                           int num_images) {
  Config config;
  SyntheticSource source(scene, SyntheticConfig::load(config));
  auto extractor = makeFeatureExtractor(TrackingConfig());
  std::vector<cv::Mat> descriptors;
  const int step = std::max(1, source.frameCount() / std::max(1, num_images));
  for (int index = 0; index < source.frameCount(); index += step) {
    const RgbdFramePtr frame = source.renderFrame(index);
    cv::Mat gray = frame->gray;
    if (gray.empty()) cv::cvtColor(frame->color_bgr, gray, cv::COLOR_BGR2GRAY);
    FeatureSet features;
    extractor->extract(gray, features);
    descriptors.push_back(features.descriptors);
  }
  return Vocabulary::train(descriptors, branching, depth, 42);
}

}  // namespace slamd
