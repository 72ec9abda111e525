// Training and loading of the daemon's vocabulary (needs the synthetic worlds and the front end).

#include <chrono>

#include <opencv2/imgproc.hpp>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/common/log.hpp"
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

std::shared_ptr<const Vocabulary> loadOrTrainVocabulary(const BackendConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  const auto elapsed_s = [&]() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  if (!config.vocabulary_file.empty()) {
    auto vocabulary = std::make_shared<const Vocabulary>(Vocabulary::load(config.vocabulary_file));
    SLAMD_LOG_INFO("backend") << "vocabulary loaded from " << config.vocabulary_file << ": "
                              << vocabulary->numWords() << " words in " << elapsed_s() << " s";
    return vocabulary;
  }
  auto vocabulary = std::make_shared<const Vocabulary>(trainVocabularyOnSyntheticScene(
      "room", config.vocabulary_branching, config.vocabulary_depth));
  SLAMD_LOG_INFO("backend") << "vocabulary trained on the synthetic room: "
                            << vocabulary->numWords() << " words in " << elapsed_s()
                            << " s (set backend.vocabulary_file to load one)";
  return vocabulary;
}

}  // namespace slamd
