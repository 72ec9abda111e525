// Vocabulary files: round trip, and every kind of damage gives a clear error, never a crash.

#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/vocabulary.hpp"

namespace slamd {
namespace {

// Random 256-bit descriptors around a few centres, so the tree has real structure.
std::vector<cv::Mat> randomDescriptors(int images, int per_image) {
  std::mt19937 rng(42);
  std::vector<cv::Mat> centres;
  for (int c = 0; c < 16; ++c) {
    cv::Mat centre(1, 32, CV_8UC1);
    cv::randu(centre, 0, 256);
    centres.push_back(centre);
  }
  cv::RNG cv_rng(42);
  std::vector<cv::Mat> out;
  for (int i = 0; i < images; ++i) {
    cv::Mat d(per_image, 32, CV_8UC1);
    for (int r = 0; r < per_image; ++r) {
      centres[static_cast<std::size_t>(rng() % centres.size())].copyTo(d.row(r));
      for (int flip = 0; flip < 20; ++flip) {
        d.at<std::uint8_t>(r, cv_rng.uniform(0, 32)) ^=
            static_cast<std::uint8_t>(1u << cv_rng.uniform(0, 8));
      }
    }
    out.push_back(d);
  }
  return out;
}

const Vocabulary& smallVocabulary() {
  static const Vocabulary vocabulary = Vocabulary::train(randomDescriptors(10, 200), 4, 3, 42);
  return vocabulary;
}

std::string serialised(const Vocabulary& vocabulary) {
  std::stringstream buffer;
  vocabulary.write(buffer);
  return buffer.str();
}

std::string tempPath(const std::string& name) {
  return ::testing::TempDir() + "slamd_vocabulary_" + name;
}

TEST(VocabularyFile, RoundTripGivesTheSameWordsAndShape) {
  const Vocabulary& vocabulary = smallVocabulary();
  ASSERT_FALSE(vocabulary.empty());
  const std::string path = tempPath("round_trip.voc");
  vocabulary.save(path);
  const Vocabulary copy = Vocabulary::load(path);
  EXPECT_EQ(copy.numWords(), vocabulary.numWords());
  EXPECT_EQ(copy.branching(), 4);
  EXPECT_EQ(copy.depth(), 3);
  const cv::Mat probe = randomDescriptors(1, 300)[0];
  for (int r = 0; r < probe.rows; ++r) {
    EXPECT_EQ(copy.word(binaryDescriptorRow(probe, r)),
              vocabulary.word(binaryDescriptorRow(probe, r)));
  }
  EXPECT_EQ(serialised(copy), serialised(vocabulary));
  std::remove(path.c_str());
}

TEST(VocabularyFile, EveryTruncationIsReportedAndLeavesTheVocabularyUnchanged) {
  const std::string bytes = serialised(smallVocabulary());
  Vocabulary target = smallVocabulary();
  for (std::size_t length = 0; length < bytes.size(); length += 7) {
    std::istringstream in(bytes.substr(0, length));
    std::string error;
    EXPECT_FALSE(target.read(in, &error)) << length;
    EXPECT_FALSE(error.empty());
  }
  EXPECT_EQ(serialised(target), bytes);
}

TEST(VocabularyFile, CorruptBytesFailTheChecksumOrValidation) {
  const std::string bytes = serialised(smallVocabulary());
  std::mt19937 rng(42);
  for (int trial = 0; trial < 200; ++trial) {
    std::string damaged = bytes;
    const std::size_t at = rng() % damaged.size();
    damaged[at] = static_cast<char>(damaged[at] ^ static_cast<char>(1 + rng() % 255));
    std::istringstream in(damaged);
    Vocabulary v;
    std::string error;
    EXPECT_FALSE(v.read(in, &error)) << "byte " << at;
    EXPECT_FALSE(error.empty());
  }
}

TEST(VocabularyFile, WrongVersionAndForeignFilesGiveClearErrors) {
  std::string bytes = serialised(smallVocabulary());
  bytes[8] = 99;  // the version follows the 8-byte magic
  std::istringstream in(bytes);
  Vocabulary v;
  std::string error;
  EXPECT_FALSE(v.read(in, &error));
  EXPECT_NE(error.find("version 99"), std::string::npos) << error;
  std::istringstream garbage("not a vocabulary at all");
  EXPECT_FALSE(v.read(garbage, &error));
  EXPECT_NE(error.find("magic"), std::string::npos) << error;

  const std::string path = tempPath("truncated.voc");
  {
    std::ofstream out(path, std::ios::binary);
    const std::string good = serialised(smallVocabulary());
    out << good.substr(0, good.size() / 2);
  }
  try {
    Vocabulary::load(path);
    ADD_FAILURE() << "a truncated file loaded";
  } catch (const VocabularyError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
  std::remove(path.c_str());
  EXPECT_THROW(Vocabulary::load(tempPath("does_not_exist.voc")), VocabularyError);
}

TEST(VocabularyFile, LoadVocabularyLoadsTheConfiguredFile) {
  const std::string path = tempPath("configured.voc");
  smallVocabulary().save(path);
  BackendConfig config;
  config.vocabulary_file = path;
  const auto loaded = loadVocabulary(config);
  ASSERT_NE(loaded, nullptr);
  EXPECT_EQ(serialised(*loaded), serialised(smallVocabulary()));
  std::remove(path.c_str());
}

TEST(VocabularyFile, AMissingOrCorruptFileIsAnErrorNamingIt) {
  BackendConfig config;
  config.vocabulary_file = tempPath("missing.voc");
  try {
    loadVocabulary(config);
    ADD_FAILURE() << "a missing file loaded";
  } catch (const VocabularyError& e) {
    EXPECT_NE(std::string(e.what()).find(config.vocabulary_file), std::string::npos) << e.what();
  }
  config.vocabulary_file = tempPath("corrupt.voc");
  std::string bytes = serialised(smallVocabulary());
  bytes[bytes.size() / 2] ^= 0x5a;  // caught by the checksum
  std::ofstream(config.vocabulary_file, std::ios::binary) << bytes;
  try {
    loadVocabulary(config);
    ADD_FAILURE() << "a corrupt file loaded";
  } catch (const VocabularyError& e) {
    EXPECT_NE(std::string(e.what()).find(config.vocabulary_file), std::string::npos) << e.what();
  }
  std::remove(config.vocabulary_file.c_str());
}

TEST(VocabularyFile, TheBuiltVocabularyIsFoundNextToTheProgram) {
  // Test programs live in <build>/bin like slamd; the build writes <build>/share/slamd/.
  const std::string path = defaultVocabularyPath();
  EXPECT_NE(path.find("share/slamd/orb_vocabulary.voc"), std::string::npos) << path;
  const auto built = loadVocabulary(BackendConfig());  // empty vocabulary_file: the built one
  ASSERT_NE(built, nullptr);
  EXPECT_EQ(built->branching(), BackendConfig().vocabulary_branching);
  EXPECT_EQ(built->depth(), BackendConfig().vocabulary_depth);
  EXPECT_GT(built->numWords(), 100);
}

TEST(BackendConfig, ReadsTheVocabularyFileAndBackEndKeys) {
  Config config = Config::fromYamlString(
      "backend:\n  vocabulary_file: /tmp/x.voc\n  local_edges: 3\n  relocalization: false\n");
  const BackendConfig c = BackendConfig::load(config);
  EXPECT_EQ(c.vocabulary_file, "/tmp/x.voc");
  EXPECT_EQ(c.local_edges, 3);
  EXPECT_FALSE(c.relocalization);
  Config bad = Config::fromYamlString("backend:\n  local_edges: -1\n");
  EXPECT_THROW(BackendConfig::load(bad), ConfigError);
}

}  // namespace
}  // namespace slamd
