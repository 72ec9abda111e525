// The daemon's vocabulary: a file trained by slamd-vocabulary (built and installed with slamd).

#include <chrono>
#include <filesystem>
#include <system_error>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/common/log.hpp"

namespace slamd {

std::string defaultVocabularyPath() {
  std::error_code error;
  const std::filesystem::path program = std::filesystem::read_symlink("/proc/self/exe", error);
  const std::filesystem::path bin = error ? std::filesystem::path(".") : program.parent_path();
  return (bin / ".." / kVocabularyInstallDir / kVocabularyFileName).lexically_normal().string();
}

std::shared_ptr<const Vocabulary> loadVocabulary(const BackendConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  const std::string path =
      config.vocabulary_file.empty() ? defaultVocabularyPath() : config.vocabulary_file;
  std::shared_ptr<const Vocabulary> vocabulary;
  try {
    vocabulary = std::make_shared<const Vocabulary>(Vocabulary::load(path));
  } catch (const VocabularyError& e) {
    throw VocabularyError(
        std::string(e.what()) +
        (config.vocabulary_file.empty()
             ? " (the vocabulary built with slamd; rebuild, or write one with slamd-vocabulary "
               "--out FILE and set backend.vocabulary_file)"
             : " (write one with slamd-vocabulary --out FILE)"));
  }
  if (vocabulary->empty()) throw VocabularyError(path + ": the vocabulary has no words");
  SLAMD_LOG_INFO("backend")
      << "vocabulary loaded from " << path << ": " << vocabulary->numWords() << " words in "
      << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s";
  return vocabulary;
}

}  // namespace slamd
