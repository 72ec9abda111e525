#pragma once
// Locating the shared datasets for tests: $SLAMD_DATA_DIR, else ../shared/data next to the
// project. Tests that need data call GTEST_SKIP() with the message from missingDataMessage().

#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>

namespace slamd::test {

inline std::filesystem::path dataRoot() {
  if (const char* env = std::getenv("SLAMD_DATA_DIR"); env && *env) return env;
  return std::filesystem::path(SLAMD_SOURCE_DIR) / ".." / "shared" / "data";
}

/// The dataset folder `name` under the data root, or nullopt when it is absent.
inline std::optional<std::filesystem::path> findDataset(const std::string& name) {
  const auto path = dataRoot() / name;
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) return std::filesystem::canonical(path);
  return std::nullopt;
}

inline std::string missingDataMessage(const std::string& name) {
  return "dataset '" + name + "' not found under " + dataRoot().string() +
         " (set SLAMD_DATA_DIR to the folder holding it); skipping";
}

}  // namespace slamd::test
