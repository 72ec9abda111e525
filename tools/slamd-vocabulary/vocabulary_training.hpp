#pragma once
// Vocabulary training on slamd's synthetic worlds: used by slamd-vocabulary (which writes the
// vocabulary the build installs) and by evaluations that need a vocabulary of another scene.
// The daemon never trains: it loads a file (loadVocabulary in slamd/backend/vocabulary.hpp).

#include <string>

#include "slamd/backend/vocabulary.hpp"

namespace slamd {

/// Trains a vocabulary on ORB descriptors (tracking's default extractor) of `num_images` frames
/// evenly spread over one of slamd's synthetic scenes (room, corridor, corridor_loop; default
/// synthetic settings). Deterministic.
Vocabulary trainVocabularyOnSyntheticScene(const std::string& scene, int branching, int depth,
                                           int num_images = 20);

}  // namespace slamd
