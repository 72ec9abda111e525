// The configuration reference against what the program reads: every key loaded by some area is
// described (and nothing else), keys are declared once, the sample files load without unknown
// keys, and the README's reference is the schema's.

#include "slamd/app/config_reference.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "slamd/mapping/mapping_config.hpp"

namespace slamd {
namespace {

std::vector<std::string> describedKeys(const std::string& area = "") {
  std::vector<std::string> keys;
  for (const auto& key : describeConfiguration(area)) keys.push_back(key.key);
  return keys;
}

TEST(ConfigReference, DescribesExactlyTheKeysTheProgramReads) {
  Config config;
  loadEveryConfigArea(config);
  std::vector<std::string> described = describedKeys();
  std::sort(described.begin(), described.end());
  EXPECT_EQ(config.usedKeys(), described);
}

TEST(ConfigReference, EachKeyIsDeclaredOnce) {
  std::set<std::string> seen;
  for (const auto& key : describedKeys()) EXPECT_TRUE(seen.insert(key).second) << key;
}

TEST(ConfigReference, EveryKeyHasATypeAndADoc) {
  for (const auto& key : describeConfiguration("")) {
    EXPECT_FALSE(key.doc.empty()) << key.key;
    EXPECT_FALSE(key.type.empty()) << key.key;
    if (key.has_range) {
      EXPECT_LE(key.min_value, key.max_value) << key.key;
    }
  }
}

TEST(ConfigReference, DescribedDefaultsAreTheLoadedDefaults) {
  // Loading the described default of every key (as an override) changes nothing: the effective
  // configuration is the same as with no file at all.
  Config defaults;
  loadEveryConfigArea(defaults);
  Config explicit_defaults;
  for (const auto& key : describeConfiguration("")) {
    if (key.key == "camera.depth_scale" || key.key == "capture.lcm.url") continue;  // by source
    explicit_defaults.set(key.key, key.default_value);
  }
  loadEveryConfigArea(explicit_defaults);
  EXPECT_EQ(explicit_defaults.effectiveYaml(), defaults.effectiveYaml());
}

TEST(ConfigReference, OneArea) {
  const auto mapping = describedKeys("mapping");
  ASSERT_FALSE(mapping.empty());
  for (const auto& key : mapping) EXPECT_EQ(key.rfind("mapping.", 0), 0u) << key;
  EXPECT_NE(std::find(mapping.begin(), mapping.end(), "mapping.enabled"), mapping.end());
  EXPECT_THROW(describeConfiguration("nonsense"), ConfigError);
}

TEST(ConfigReference, SampleFilesHaveNoUnknownKeys) {
  const std::filesystem::path folder = std::filesystem::path(SLAMD_SOURCE_DIR) / "config";
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    if (entry.path().extension() != ".yaml") continue;
    ++files;
    Config config = Config::fromFile(entry.path().string());
    loadEveryConfigArea(config);
    EXPECT_EQ(config.unknownKeys(), std::vector<std::string>()) << entry.path();
  }
  EXPECT_GT(files, 0);
}

TEST(ConfigReference, RangeErrorNamesTheKey) {
  MappingConfig mapping;
  EXPECT_EQ(mapping.validationError(), "");
  mapping.resolution_m = 2.0;
  EXPECT_NE(mapping.validationError().find("mapping.resolution_m"), std::string::npos);
  mapping = MappingConfig();
  mapping.occupancy_threshold = 0.1;  // in range, below clamp_min: a cross-field check
  EXPECT_NE(mapping.validationError().find("strictly between"), std::string::npos);
}

TEST(ConfigReference, ReadmeMatchesSchema) {
  std::ifstream file(std::filesystem::path(SLAMD_SOURCE_DIR) / "README.md");
  std::stringstream text;
  text << file.rdbuf();
  const std::string readme = text.str();
  const std::string begin_marker = "<!-- BEGIN CONFIG REFERENCE";
  const std::string end_marker = "<!-- END CONFIG REFERENCE -->";
  const auto begin = readme.find(begin_marker);
  const auto end = readme.find(end_marker);
  ASSERT_NE(begin, std::string::npos);
  ASSERT_NE(end, std::string::npos);
  const auto body_begin = readme.find('\n', begin) + 1;
  const std::string in_readme = readme.substr(body_begin, end - body_begin);
  const std::string expected = "\n" + configReferenceMarkdown(describeConfiguration("")) + "\n";
  EXPECT_EQ(in_readme, expected) << "the README's configuration reference is out of date: run "
                                    "scripts/update-config-reference.sh";
}

}  // namespace
}  // namespace slamd
