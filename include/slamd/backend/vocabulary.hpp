#pragma once
// Vocabulary: a bag-of-words vocabulary tree over 256-bit binary descriptors (ORB), trained by
// slamd itself with hierarchical k-majority clustering (k-means for Hamming space: centres are
// bitwise majorities of their members, seeded k-means++ style), TF-IDF weighted.
//
// Usage (build once, then read-only; safe to share between threads once built):
//   std::vector<cv::Mat> training;                  // ORB descriptors, one Mat per image
//   Vocabulary vocabulary = Vocabulary::train(training, /*branching=*/8, /*depth=*/3, 42);
//   BowVector a = vocabulary.transform(keyframe_a.features.descriptors);
//   BowVector b = vocabulary.transform(keyframe_b.features.descriptors);
//   double similarity = bowScore(a, b);              // 0 = nothing in common, 1 = identical
//
// A descriptor is quantised by descending the tree to the nearest centre (Hamming distance) at
// every level; the leaf is its word. Word weights: tf-idf, tf = occurrences / descriptors in the
// image, idf = log(training images / training images containing the word). Vectors are
// L1-normalised and compared with the L1 score 1 - |a - b|_1 / 2 = sum over common words of
// min(a_w, b_w).

#include <array>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

namespace slamd {

/// A 256-bit binary descriptor as four 64-bit words.
using BinaryDescriptor = std::array<std::uint64_t, 4>;

int hammingDistance(const BinaryDescriptor& a, const BinaryDescriptor& b);
/// Row `row` of a CV_8U descriptor matrix with 32 columns.
BinaryDescriptor binaryDescriptorRow(const cv::Mat& descriptors, int row);

/// Sparse word weights, sorted by word id, L1-normalised (sum of weights 1, or empty).
using BowVector = std::vector<std::pair<int, double>>;

/// Similarity of two L1-normalised BoW vectors in [0, 1].
double bowScore(const BowVector& a, const BowVector& b);

class Vocabulary {
 public:
  /// Trains a tree of at most branching^depth words from descriptors of several images (each a
  /// CV_8U matrix with 32 columns; other types are skipped). Deterministic for a given seed.
  /// An empty training set gives an empty vocabulary (transform() then returns empty vectors).
  static Vocabulary train(const std::vector<cv::Mat>& image_descriptors, int branching, int depth,
                          std::uint64_t seed);

  bool empty() const { return num_words_ == 0; }
  int numWords() const { return num_words_; }
  /// The word of one descriptor (-1 for an empty vocabulary).
  int word(const BinaryDescriptor& descriptor) const;
  /// The tf-idf vector of one image's descriptors (CV_8U, 32 columns; else empty).
  BowVector transform(const cv::Mat& descriptors) const;
  double idf(int word) const { return idf_[static_cast<std::size_t>(word)]; }

  int branching() const { return branching_; }
  int depth() const { return depth_; }

  /// Binary serialisation, format version kFileVersion (little-endian): magic
  /// "SLAMDVOC", version, branching, depth, node and word counts, payload size, the nodes
  /// (centre, word, children), the idf weights, and an FNV-1a checksum of everything after the
  /// magic.
  void write(std::ostream& out) const;
  /// Reads what write() wrote; false (and *error says why: not a vocabulary, unsupported
  /// version, truncated, checksum mismatch, inconsistent tree) on malformed input, leaving this
  /// vocabulary unchanged. Never crashes on arbitrary bytes.
  bool read(std::istream& in, std::string* error = nullptr);

  /// write() to a file, crash-safely (writeFileAtomically); throws VocabularyError.
  void save(const std::string& path) const;
  /// read() from a regular file; throws VocabularyError naming the file and the problem.
  static Vocabulary load(const std::string& path);

  static constexpr std::uint32_t kFileVersion = 2;

 private:
  struct Node {
    BinaryDescriptor centre{};
    std::vector<int> children;  ///< node indices; empty for a leaf
    int word = -1;              ///< word id of a leaf
  };
  void build(int node, const std::vector<BinaryDescriptor>& data, const std::vector<int>& members,
             int level, int branching, int depth, std::uint64_t seed);

  std::vector<Node> nodes_;  ///< nodes_[0] is the root
  std::vector<double> idf_;  ///< per word
  int num_words_ = 0;
  int branching_ = 0;
  int depth_ = 0;
};

/// A vocabulary file that cannot be read or written.
class VocabularyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct BackendConfig;

/// Where the vocabulary built with slamd lives, relative to the program's folder: the build
/// writes it to <build>/share/slamd/, `cmake --install` to <prefix>/share/slamd/ (slamd-vocabulary
/// trains it; tools/slamd-vocabulary/CMakeLists.txt).
inline constexpr const char* kVocabularyInstallDir = "share/slamd";
inline constexpr const char* kVocabularyFileName = "orb_vocabulary.voc";

/// <folder of the running program>/../share/slamd/orb_vocabulary.voc.
std::string defaultVocabularyPath();

/// The daemon's vocabulary, read from backend.vocabulary_file, or defaultVocabularyPath() when
/// that is empty. Never trains (training renders a scene: slamd-vocabulary does it at build
/// time). Throws VocabularyError naming the file when it is missing, corrupt or empty.
std::shared_ptr<const Vocabulary> loadVocabulary(const BackendConfig& config);

}  // namespace slamd
