#pragma once
// What slamd-backend-eval and slamd-place-eval start from: the configuration, the open frame
// source and the back end's vocabulary.

#include <memory>
#include <string>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/tracking/tracking_config.hpp"

namespace slamd {

struct BackendEvalSetup {
  Config config;
  BackendConfig backend;
  TrackingConfig tracking;
  std::unique_ptr<FrameSource> source;  ///< open
  std::shared_ptr<const Vocabulary> vocabulary;
  double vocabulary_ready_s = 0.0;  ///< time to load or train it
};

/// Loads --config (config/synthetic.yaml for a synthetic source, config/tum_fr1.yaml otherwise,
/// by default) with its --set overrides, opens `source_spec` and loads the vocabulary: the file
/// --vocabulary names, else backend.vocabulary_file, else one trained on the synthetic scene
/// --vocabulary-scene as the build trains it. The options must declare --vocabulary and
/// --vocabulary-scene. Returns 0, or the exit code after printing what went wrong.
int openBackendEvalSetup(const ProgramOptions& options, const std::string& source_spec,
                         BackendEvalSetup& setup);

}  // namespace slamd
