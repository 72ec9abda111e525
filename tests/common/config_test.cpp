#include "slamd/common/config.hpp"

#include <filesystem>
#include <fstream>
#include <utility>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

constexpr const char* kYaml = R"(
tracking:
  frontend: fovis
  max_features: 800
  ratio: 0.75
  enabled: true
camera:
  distortion: [0.1, -0.2, 0.0, 0.0, 0.3]
mapping:
  resolution_m: 0.05
)";

TEST(Config, ReadsTypedValuesFromYaml) {
  Config config = Config::fromYamlString(kYaml);
  EXPECT_EQ(config.getChoice("tracking.frontend", "orb", {"orb", "sift", "fovis"}), "fovis");
  EXPECT_EQ(config.getInt("tracking.max_features", 1000, 10, 10000), 800);
  EXPECT_DOUBLE_EQ(config.getDouble("tracking.ratio", 0.8, 0.0, 1.0), 0.75);
  EXPECT_TRUE(config.getBool("tracking.enabled", false));
  const auto distortion = config.getDoubleList("camera.distortion", {}, 5);
  ASSERT_EQ(distortion.size(), 5u);
  EXPECT_DOUBLE_EQ(distortion[2], 0.0);
  EXPECT_DOUBLE_EQ(distortion[4], 0.3);
}

TEST(Config, MissingKeysTakeTheirDefaults) {
  Config config = Config::fromYamlString(kYaml);
  EXPECT_EQ(config.getInt("tracking.pyramid_levels", 3, 1, 8), 3);
  EXPECT_EQ(config.getString("daemon.pose_channel", "SLAMD_POSE"), "SLAMD_POSE");
}

TEST(Config, ReadsAFile) {
  const test::ScopedTempDir dir("config");
  const auto path = dir / "test.yaml";
  std::ofstream(path) << "%YAML:1.0\n---\n" << kYaml;
  Config config = Config::fromFile(path.string());
  EXPECT_EQ(config.getInt("tracking.max_features", 1000, 10, 10000), 800);
  EXPECT_EQ(config.origin(), path.string());
}

// Hostile-input issue, row 7: a file nested 50,000 deep crashed the parser (SIGSEGV), /dev/zero
// grew memory without bound, and a directory ran silently on defaults with exit 0.
TEST(Config, DeeplyNestedYamlIsAConfigErrorNotACrash) {
  const test::ScopedTempDir dir("config-nested");
  std::string indented = "a:\n";
  for (int level = 1; indented.size() < 900000; ++level) {
    indented += std::string(static_cast<std::size_t>(level), ' ') + "b:\n";
  }
  const std::string flow = "a: " + std::string(50000, '[') + std::string(50000, ']') + "\n";
  std::string dashes = "a:\n";
  for (int level = 0; level < 50000; ++level) dashes += "- ";
  dashes += "x\n";
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"indented", indented},
                                   {"flow", flow},
                                   {"dashes", dashes}}) {
    const auto path = dir / (name + ".yaml");
    std::ofstream(path) << text;
    try {
      Config::fromFile(path.string());
      ADD_FAILURE() << name << ": no error";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find("nested more than 64"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
  }
}

TEST(Config, ADeviceADirectoryOrAHugeFileIsRefusedNamingIt) {
  const test::ScopedTempDir dir("config-special");
  const auto huge = dir / "huge.yaml";
  std::ofstream(huge) << "# " << std::string(2 << 20, 'x') << "\n";
  for (const std::string& path : {std::string("/dev/zero"), dir.string(), huge.string()}) {
    try {
      Config::fromFile(path);
      ADD_FAILURE() << path << ": no error";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
}

TEST(Config, ReadsAFileWithoutYamlDirective) {
  const test::ScopedTempDir dir("config");
  const auto path = dir / "plain.yaml";
  std::ofstream(path) << kYaml;
  Config config = Config::fromFile(path.string());
  EXPECT_EQ(config.getInt("tracking.max_features", 1000, 10, 10000), 800);
}

TEST(Config, InlineCommentsAreNotPartOfValues) {
  Config config = Config::fromYamlString(
      "a:\n  flag: false   # explanation\n  count: 3  # three\n  name: orb # the default\n"
      "  quoted: \"x # y\"\n  hash: a#b\n");
  EXPECT_FALSE(config.getBool("a.flag", true));
  EXPECT_EQ(config.getInt("a.count", 0, 0, 10), 3);
  EXPECT_EQ(config.getString("a.name", ""), "orb");
  EXPECT_EQ(config.getString("a.hash", ""), "a#b");
}

TEST(Config, MissingFileIsAConfigError) {
  EXPECT_THROW(Config::fromFile("/nonexistent/slamd.yaml"), ConfigError);
}

TEST(Config, OutOfRangeValueNamesKeyValueAndRange) {
  Config config = Config::fromYamlString(kYaml);
  try {
    config.getInt("tracking.max_features", 1000, 1000, 5000);
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("tracking.max_features"), std::string::npos) << message;
    EXPECT_NE(message.find("800"), std::string::npos) << message;
    EXPECT_NE(message.find("[1000, 5000]"), std::string::npos) << message;
  }
}

TEST(Config, WrongTypesAreErrors) {
  Config config =
      Config::fromYamlString("a:\n  number: abc\n  flag: maybe\n  list: 3\n  int: 2.5\n");
  EXPECT_THROW(config.getDouble("a.number", 0.0, 0.0, 1.0), ConfigError);
  EXPECT_THROW(config.getBool("a.flag", false), ConfigError);
  EXPECT_THROW(config.getDoubleList("a.list", {}), ConfigError);
  EXPECT_THROW(config.getInt("a.int", 0, 0, 10), ConfigError);
}

TEST(Config, ChoiceOutsideTheAllowedSetIsAnError) {
  Config config = Config::fromYamlString("tracking:\n  frontend: surf\n");
  try {
    config.getChoice("tracking.frontend", "orb", {"orb", "sift", "fovis"});
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("orb, sift, fovis"), std::string::npos) << e.what();
  }
}

TEST(Config, ListOfTheWrongLengthIsAnError) {
  Config config = Config::fromYamlString(kYaml);
  EXPECT_THROW(config.getDoubleList("camera.distortion", {}, 4), ConfigError);
}

TEST(Config, UnknownKeysAreReported) {
  Config config = Config::fromYamlString(kYaml);
  config.getChoice("tracking.frontend", "orb", {"orb", "sift", "fovis"});
  config.getInt("tracking.max_features", 1000, 10, 10000);
  config.getDouble("tracking.ratio", 0.8, 0.0, 1.0);
  config.getBool("tracking.enabled", false);
  config.getDoubleList("camera.distortion", {}, 5);
  const auto unknown = config.unknownKeys();
  ASSERT_EQ(unknown.size(), 1u);
  EXPECT_EQ(unknown[0], "mapping.resolution_m");
}

TEST(Config, OverrideReplacesFileValue) {
  Config config = Config::fromYamlString(kYaml);
  config.applyOverride("tracking.max_features=1500");
  config.applyOverride("camera.distortion=[1, 2, 3, 4, 5]");
  config.applyOverride("new.key = value");
  EXPECT_EQ(config.getInt("tracking.max_features", 1000, 10, 10000), 1500);
  EXPECT_DOUBLE_EQ(config.getDoubleList("camera.distortion", {}, 5)[4], 5.0);
  EXPECT_EQ(config.getString("new.key", ""), "value");
}

TEST(Config, MalformedOverrideIsAnError) {
  Config config;
  EXPECT_THROW(config.applyOverride("no_equals_sign"), ConfigError);
  EXPECT_THROW(config.applyOverride("nosection=3"), ConfigError);
  EXPECT_THROW(config.applyOverride("=3"), ConfigError);
}

TEST(Config, EffectiveYamlListsEveryValueUsedIncludingDefaults) {
  Config config = Config::fromYamlString(kYaml);
  config.getInt("tracking.max_features", 1000, 10, 10000);
  config.getInt("tracking.pyramid_levels", 3, 1, 8);
  const std::string yaml = config.effectiveYaml();
  EXPECT_NE(yaml.find("tracking:\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("  max_features: 800\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("  pyramid_levels: 3\n"), std::string::npos) << yaml;
  // The effective YAML reads back to the same values.
  Config reread = Config::fromYamlString(yaml);
  EXPECT_EQ(reread.getInt("tracking.max_features", 0, 0, 10000), 800);
}

TEST(Config, EveryShippedConfigFileParses) {
  const auto dir = std::filesystem::path(SLAMD_SOURCE_DIR) / "config";
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".yaml") continue;
    ++files;
    EXPECT_NO_THROW(Config::fromFile(entry.path().string())) << entry.path();
  }
  EXPECT_GE(files, 6);
}

// Fuzzing found text on which cv::FileStorage, the previous reader, looped forever; slamd now
// reads its YAML subset itself and refuses everything else with the line.
TEST(Config, TextTheOldParserHungOnIsRefusedAtOnce) {
  try {
    Config::fromYamlString(" t:0\n2, -\nb");
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("line 1"), std::string::npos) << e.what();
  }
}

TEST(Config, YamlSubsetReadsNestingSequencesAndQuotes) {
  Config config = Config::fromYamlString(
      "%YAML:1.0\n---\na:\n  b:\n    c: 1   # comment\n  list: [1, 2,\n         3]\n"
      "  items:\n    - x\n    - 'y z'\n  same_indent:\n  - 4\n  - 5\n  quoted: \"q: #r\"\n"
      "  empty:\nd: 2\n...\nignored: after the end marker\n");
  EXPECT_EQ(config.getInt("a.b.c", 0, 0, 10), 1);
  EXPECT_EQ(config.getString("a.list", ""), "[1, 2, 3]");
  EXPECT_EQ(config.getString("a.items", ""), "[x, y z]");
  EXPECT_EQ(config.getString("a.same_indent", ""), "[4, 5]");
  EXPECT_EQ(config.getString("a.quoted", ""), "q: #r");
  EXPECT_EQ(config.getString("a.empty", "default"), "");
  EXPECT_EQ(config.getInt("d", 0, 0, 10), 2);
  EXPECT_FALSE(config.has("ignored"));
}

TEST(Config, YamlOutsideTheSubsetIsRefusedNamingTheLine) {
  const std::pair<std::string, std::string> cases[] = {
      {"a: 1\nb: &anchor 2\n", "line 2"},      // anchors
      {"a:\n\tb: 1\n", "line 2: a tab"},       // tab indentation
      {"a: {b: 1}\n", "line 1"},               // flow mapping
      {"a: [1, [2, 3]]\n", "line 1: nested"},  // nested sequence
      {"a: [1, 2\n", "never closed"},          // unclosed
      {"a: 1\na: 2\n", "given twice"},         // duplicate key
      {"a: 1\n  b: 2\n", "line 2: unexpected indentation"},
      {"a: \"open\n", "unclosed quote"},
      {"a: 1\x01\n", "control character"},
      {std::string("a: 1\0b\n", 7), "line 1: control character 0"},
      {"- a\n", "list item where a key"},
      {"a b: 1\n", "expected 'key: value'"},
  };
  for (const auto& [text, expected] : cases) {
    try {
      Config::fromYamlString(text);
      ADD_FAILURE() << "no error for: " << text;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos)
          << "for " << text << ": " << e.what();
    }
  }
}

}  // namespace
}  // namespace slamd
