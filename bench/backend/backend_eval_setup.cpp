#include "backend_eval_setup.hpp"

#include <chrono>
#include <iostream>

#include "slamd/backend/backend.hpp"
#include "slamd/sources/create_frame_source.hpp"
#include "vocabulary_training.hpp"

namespace slamd {

int openBackendEvalSetup(const ProgramOptions& options, const std::string& source_spec,
                         BackendEvalSetup& setup) {
  const bool synthetic = source_spec.rfind("synthetic:", 0) == 0;
  try {
    setup.config = options.loadConfig(synthetic ? SLAMD_SOURCE_DIR "/config/synthetic.yaml"
                                                : SLAMD_SOURCE_DIR "/config/tum_fr1.yaml");
    setup.backend = BackendConfig::load(setup.config);
    setup.tracking = TrackingConfig::load(setup.config);
    setup.source = createFrameSource(source_spec, setup.config);
    setup.source->open();
    const auto t0 = std::chrono::steady_clock::now();
    if (options.has("vocabulary")) setup.backend.vocabulary_file = options.value("vocabulary");
    if (!setup.backend.vocabulary_file.empty()) {
      setup.vocabulary = loadVocabulary(setup.backend);
    } else {
      setup.vocabulary = std::make_shared<const Vocabulary>(trainVocabularyOnSyntheticScene(
          options.value("vocabulary-scene"), setup.backend.vocabulary_branching,
          setup.backend.vocabulary_depth));
    }
    setup.vocabulary_ready_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  } catch (const ConfigError& e) {
    std::cerr << e.what() << "\n";
    return kExitConfigError;
  } catch (const SourceError& e) {
    std::cerr << e.what() << "\n";
    return kExitSourceError;
  } catch (const VocabularyError& e) {
    std::cerr << e.what() << "\n";
    return kExitConfigError;
  }
  return 0;
}

}  // namespace slamd
