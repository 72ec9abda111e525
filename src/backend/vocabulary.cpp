#include "slamd/backend/vocabulary.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <istream>
#include <limits>
#include <map>
#include <ostream>
#include <random>
#include <set>
#include <sstream>
#include <string>

#include "slamd/common/binary_codec.hpp"
#include "slamd/common/file_io.hpp"

namespace slamd {

namespace {

// Bit count of a 64-bit word without the POPCNT instruction (the build targets baseline x86-64,
// where __builtin_popcountll becomes a slow library call): the classic SWAR reduction.
inline int popcount64(std::uint64_t x) {
  x = x - ((x >> 1) & 0x5555555555555555ull);
  x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
  x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0full;
  return static_cast<int>((x * 0x0101010101010101ull) >> 56);
}

}  // namespace

int hammingDistance(const BinaryDescriptor& a, const BinaryDescriptor& b) {
  return popcount64(a[0] ^ b[0]) + popcount64(a[1] ^ b[1]) + popcount64(a[2] ^ b[2]) +
         popcount64(a[3] ^ b[3]);
}

BinaryDescriptor binaryDescriptorRow(const cv::Mat& descriptors, int row) {
  BinaryDescriptor d{};
  std::memcpy(d.data(), descriptors.ptr<std::uint8_t>(row), sizeof(d));
  return d;
}

double bowScore(const BowVector& a, const BowVector& b) {
  double score = 0.0;
  auto ia = a.begin();
  auto ib = b.begin();
  while (ia != a.end() && ib != b.end()) {
    if (ia->first < ib->first) {
      ++ia;
    } else if (ib->first < ia->first) {
      ++ib;
    } else {
      score += std::min(ia->second, ib->second);
      ++ia;
      ++ib;
    }
  }
  return score;
}

namespace {

bool isBinary256(const cv::Mat& descriptors) {
  return !descriptors.empty() && descriptors.type() == CV_8UC1 && descriptors.cols == 32;
}

// Bitwise majority of the members' descriptors (ties give 0).
BinaryDescriptor majority(const std::vector<BinaryDescriptor>& data,
                          const std::vector<int>& members) {
  std::array<int, 256> counts{};
  for (int m : members) {
    for (int w = 0; w < 4; ++w) {
      std::uint64_t bits = data[static_cast<std::size_t>(m)][static_cast<std::size_t>(w)];
      while (bits != 0) {
        const int b = __builtin_ctzll(bits);
        ++counts[static_cast<std::size_t>(64 * w + b)];
        bits &= bits - 1;
      }
    }
  }
  BinaryDescriptor centre{};
  const int half = static_cast<int>(members.size()) / 2;
  for (int bit = 0; bit < 256; ++bit) {
    if (counts[static_cast<std::size_t>(bit)] > half) {
      centre[static_cast<std::size_t>(bit / 64)] |= std::uint64_t{1} << (bit % 64);
    }
  }
  return centre;
}

}  // namespace

void Vocabulary::build(int node, const std::vector<BinaryDescriptor>& data,
                       const std::vector<int>& members, int level, int branching, int depth,
                       std::uint64_t seed) {
  const int n = static_cast<int>(members.size());
  if (level == depth || n <= branching) {
    nodes_[static_cast<std::size_t>(node)].word = num_words_++;
    return;
  }
  std::mt19937_64 rng(seed + static_cast<std::uint64_t>(node) * 7919u);
  // k-means++ seeding with squared Hamming distances.
  std::vector<BinaryDescriptor> centres;
  centres.push_back(
      data[static_cast<std::size_t>(members[std::uniform_int_distribution<int>(0, n - 1)(rng)])]);
  std::vector<double> nearest_sq(static_cast<std::size_t>(n),
                                 std::numeric_limits<double>::infinity());
  while (static_cast<int>(centres.size()) < branching) {
    double total = 0.0;
    for (int i = 0; i < n; ++i) {
      const double d = hammingDistance(data[static_cast<std::size_t>(members[i])], centres.back());
      nearest_sq[static_cast<std::size_t>(i)] =
          std::min(nearest_sq[static_cast<std::size_t>(i)], d * d);
      total += nearest_sq[static_cast<std::size_t>(i)];
    }
    if (total <= 0.0) break;  // fewer distinct descriptors than clusters
    double pick = std::uniform_real_distribution<double>(0.0, total)(rng);
    int chosen = n - 1;
    for (int i = 0; i < n; ++i) {
      pick -= nearest_sq[static_cast<std::size_t>(i)];
      if (pick <= 0.0) {
        chosen = i;
        break;
      }
    }
    centres.push_back(data[static_cast<std::size_t>(members[chosen])]);
  }
  const int k = static_cast<int>(centres.size());
  std::vector<int> assignment(static_cast<std::size_t>(n), -1);
  std::vector<std::vector<int>> clusters;
  constexpr int kMaxIterations = 10;
  for (int iteration = 0; iteration < kMaxIterations; ++iteration) {
    bool changed = false;
    for (int i = 0; i < n; ++i) {
      int best = 0;
      int best_distance = 257;
      for (int c = 0; c < k; ++c) {
        const int d = hammingDistance(data[static_cast<std::size_t>(members[i])],
                                      centres[static_cast<std::size_t>(c)]);
        if (d < best_distance) {
          best_distance = d;
          best = c;
        }
      }
      if (assignment[static_cast<std::size_t>(i)] != best) {
        assignment[static_cast<std::size_t>(i)] = best;
        changed = true;
      }
    }
    clusters.assign(static_cast<std::size_t>(k), {});
    for (int i = 0; i < n; ++i) {
      clusters[static_cast<std::size_t>(assignment[static_cast<std::size_t>(i)])].push_back(
          members[i]);
    }
    if (!changed && iteration > 0) break;
    for (int c = 0; c < k; ++c) {
      if (!clusters[static_cast<std::size_t>(c)].empty()) {
        centres[static_cast<std::size_t>(c)] =
            majority(data, clusters[static_cast<std::size_t>(c)]);
      }
    }
  }
  if (k < 2) {
    nodes_[static_cast<std::size_t>(node)].word = num_words_++;
    return;
  }
  for (int c = 0; c < k; ++c) {
    if (clusters[static_cast<std::size_t>(c)].empty()) continue;
    const int child = static_cast<int>(nodes_.size());
    nodes_.push_back(Node());
    nodes_.back().centre = centres[static_cast<std::size_t>(c)];
    nodes_[static_cast<std::size_t>(node)].children.push_back(child);
    build(child, data, clusters[static_cast<std::size_t>(c)], level + 1, branching, depth, seed);
  }
}

Vocabulary Vocabulary::train(const std::vector<cv::Mat>& image_descriptors, int branching,
                             int depth, std::uint64_t seed) {
  Vocabulary vocabulary;
  std::vector<BinaryDescriptor> data;
  for (const cv::Mat& descriptors : image_descriptors) {
    if (!isBinary256(descriptors)) continue;
    for (int r = 0; r < descriptors.rows; ++r) data.push_back(binaryDescriptorRow(descriptors, r));
  }
  if (data.empty()) return vocabulary;
  vocabulary.branching_ = std::max(branching, 2);
  vocabulary.depth_ = std::max(depth, 1);
  std::vector<int> members(data.size());
  for (std::size_t i = 0; i < data.size(); ++i) members[i] = static_cast<int>(i);
  vocabulary.nodes_.push_back(Node());
  vocabulary.build(0, data, members, 0, std::max(branching, 2), std::max(depth, 1), seed);

  // idf from the training images: log(images / images containing the word).
  std::vector<int> images_with_word(static_cast<std::size_t>(vocabulary.num_words_), 0);
  int num_images = 0;
  for (const cv::Mat& descriptors : image_descriptors) {
    if (!isBinary256(descriptors)) continue;
    ++num_images;
    std::set<int> words;
    for (int r = 0; r < descriptors.rows; ++r) {
      words.insert(vocabulary.word(binaryDescriptorRow(descriptors, r)));
    }
    for (int w : words) ++images_with_word[static_cast<std::size_t>(w)];
  }
  vocabulary.idf_.resize(images_with_word.size());
  for (std::size_t w = 0; w < images_with_word.size(); ++w) {
    vocabulary.idf_[w] =
        std::log(static_cast<double>(num_images) / std::max(1, images_with_word[w]));
  }
  return vocabulary;
}

int Vocabulary::word(const BinaryDescriptor& descriptor) const {
  if (nodes_.empty()) return -1;
  int node = 0;
  while (!nodes_[static_cast<std::size_t>(node)].children.empty()) {
    int best = -1;
    int best_distance = 257;
    for (int child : nodes_[static_cast<std::size_t>(node)].children) {
      const int d = hammingDistance(descriptor, nodes_[static_cast<std::size_t>(child)].centre);
      if (d < best_distance) {
        best_distance = d;
        best = child;
      }
    }
    node = best;
  }
  return nodes_[static_cast<std::size_t>(node)].word;
}

BowVector Vocabulary::transform(const cv::Mat& descriptors) const {
  BowVector bow;
  if (empty() || !isBinary256(descriptors)) return bow;
  std::map<int, int> counts;
  for (int r = 0; r < descriptors.rows; ++r) ++counts[word(binaryDescriptorRow(descriptors, r))];
  double total = 0.0;
  for (const auto& [w, count] : counts) {
    const double weight = count * idf_[static_cast<std::size_t>(w)] / descriptors.rows;
    if (weight > 0.0) {
      bow.emplace_back(w, weight);
      total += weight;
    }
  }
  for (auto& entry : bow) entry.second /= total;
  return bow;
}

namespace {

constexpr char kMagic[8] = {'S', 'L', 'A', 'M', 'D', 'V', 'O', 'C'};
// Bounds that no vocabulary slamd trains comes near (32^6 words at most); they keep a corrupt
// count from allocating gigabytes before the size check catches it.
constexpr std::int64_t kMaxNodes = 50000000;

bool fail(std::string* error, const std::string& message) {
  if (error != nullptr) *error = message;
  return false;
}

}  // namespace

void Vocabulary::write(std::ostream& out) const {
  std::string payload;
  LittleEndianWriter p(payload);
  for (const Node& node : nodes_) {
    for (std::uint64_t w : node.centre) p.u64(w);
    p.i32(static_cast<std::int32_t>(node.word));
    p.i32(static_cast<std::int32_t>(node.children.size()));
    for (int child : node.children) p.i32(static_cast<std::int32_t>(child));
  }
  for (double v : idf_) p.f64(v);
  LittleEndianWriter w(out);
  w.raw(kMagic, sizeof(kMagic));
  // The checksum covers the header fields after the magic and the payload.
  w.startChecksum();
  w.u32(kFileVersion);
  w.u32(static_cast<std::uint32_t>(branching_));
  w.u32(static_cast<std::uint32_t>(depth_));
  w.i64(static_cast<std::int64_t>(nodes_.size()));
  w.i64(static_cast<std::int64_t>(num_words_));
  w.u64(static_cast<std::uint64_t>(payload.size()));
  w.raw(payload.data(), payload.size());
  w.u64(w.checksum());
  w.flush();  // a failed write shows on `out`, which the caller checks
}

bool Vocabulary::read(std::istream& stream, std::string* error) {
  LittleEndianReader in(stream);
  std::vector<Node> nodes;
  std::vector<double> idf;
  std::uint32_t branching = 0;
  std::uint32_t depth = 0;
  std::int64_t num_words = 0;
  try {
    char magic[sizeof(kMagic)] = {};
    in.raw(magic, sizeof(magic));
    if (std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
      return fail(error, "not a slamd vocabulary (bad magic)");
    }
    // The checksum covers the header fields after the magic and the payload.
    in.startChecksum();
    // Each where() completes the sentence "truncated ...".
    in.setWhere("header");
    const std::uint32_t version = in.u32();
    branching = in.u32();
    depth = in.u32();
    const std::int64_t num_nodes = in.i64();
    num_words = in.i64();
    const std::uint64_t payload_size = in.u64();
    if (version != kFileVersion) {
      return fail(error, "unsupported format version " + std::to_string(version) + " (expected " +
                             std::to_string(kFileVersion) + ")");
    }
    if (num_nodes < 1 || num_nodes > kMaxNodes || num_words < 1 || num_words > num_nodes ||
        branching < 2 || branching > 1024 || depth < 1 || depth > 64) {
      return fail(error, "inconsistent header (nodes " + std::to_string(num_nodes) + ", words " +
                             std::to_string(num_words) + ")");
    }
    // Each node takes at least 40 bytes, each word 8: the declared size must fit both.
    const std::uint64_t min_size =
        static_cast<std::uint64_t>(num_nodes) * 40u + static_cast<std::uint64_t>(num_words) * 8u;
    const std::uint64_t max_size = min_size + static_cast<std::uint64_t>(num_nodes) * 4u;
    if (payload_size < min_size || payload_size > max_size) {
      return fail(error, "inconsistent payload size " + std::to_string(payload_size));
    }
    // Read in pieces, so that memory grows only with bytes really present: a 60-byte file whose
    // header declares 50 million nodes must not allocate 2 GB first.
    in.setWhere("(expected " + std::to_string(payload_size + 8) + " bytes after the header)");
    std::string payload;
    constexpr std::size_t kPiece = 1 << 20;
    while (payload.size() < payload_size) {
      const std::size_t offset = payload.size();
      const auto piece =
          static_cast<std::size_t>(std::min<std::uint64_t>(kPiece, payload_size - offset));
      payload.resize(offset + piece);
      in.raw(payload.data() + offset, piece);
    }
    const std::uint64_t computed = in.checksum();
    if (in.u64() != computed) return fail(error, "checksum mismatch (corrupt file)");

    LittleEndianReader r(payload);
    r.setWhere("node data");
    nodes.resize(static_cast<std::size_t>(num_nodes));
    std::vector<bool> has_parent(nodes.size(), false);
    std::vector<bool> word_seen(static_cast<std::size_t>(num_words), false);
    for (std::size_t index = 0; index < nodes.size(); ++index) {
      Node& node = nodes[index];
      for (std::uint64_t& w : node.centre) w = r.u64();
      const std::int32_t word = r.i32();
      const std::int32_t num_children = r.i32();
      if (word < -1 || word >= num_words || num_children < 0 || num_children > num_nodes) {
        return fail(error, "invalid node " + std::to_string(index));
      }
      node.word = word;
      for (std::int32_t c = 0; c < num_children; ++c) {
        const std::int32_t child = r.i32();
        // Children always follow their parent and have one parent: the nodes form a tree.
        if (child <= static_cast<std::int32_t>(index) || child >= num_nodes ||
            has_parent[static_cast<std::size_t>(child)]) {
          return fail(error, "invalid child of node " + std::to_string(index));
        }
        has_parent[static_cast<std::size_t>(child)] = true;
        node.children.push_back(child);
      }
      if (node.children.empty() == (node.word < 0)) {
        return fail(error, "node " + std::to_string(index) + " is neither a leaf nor inner node");
      }
      if (node.word >= 0) {
        if (word_seen[static_cast<std::size_t>(node.word)]) {
          return fail(error, "word " + std::to_string(node.word) + " appears twice");
        }
        word_seen[static_cast<std::size_t>(node.word)] = true;
      }
    }
    for (std::size_t index = 1; index < nodes.size(); ++index) {
      if (!has_parent[index]) return fail(error, "node " + std::to_string(index) + " unreachable");
    }
    r.setWhere("idf weights");
    idf.resize(static_cast<std::size_t>(num_words));
    for (double& v : idf) {
      v = r.f64();
      if (!std::isfinite(v) || v < 0.0) return fail(error, "invalid idf weight");
    }
    if (r.remaining() != 0) return fail(error, "trailing bytes in the payload");
  } catch (const TruncatedBinaryError& e) {
    // Shorter than the magic: not a vocabulary at all.
    if (in.position() < sizeof(kMagic)) return fail(error, "not a slamd vocabulary (bad magic)");
    return fail(error, "truncated " + e.where());
  }
  nodes_ = std::move(nodes);
  idf_ = std::move(idf);
  num_words_ = static_cast<int>(num_words);
  branching_ = static_cast<int>(branching);
  depth_ = static_cast<int>(depth);
  return true;
}

void Vocabulary::save(const std::string& path) const {
  std::string error;
  if (!writeFileAtomically(
          path,
          [this](std::ostream& out) {
            write(out);
            return true;
          },
          &error)) {
    throw VocabularyError("vocabulary '" + path + "': " + error);
  }
}

Vocabulary Vocabulary::load(const std::string& path) {
  // Read whole (a regular file only: a FIFO would block), then parsed from memory.
  std::vector<std::uint8_t> bytes;
  std::string error;
  if (!readFileBytes(path, bytes, error)) throw VocabularyError("vocabulary: " + error);
  std::istringstream in(std::string(bytes.begin(), bytes.end()), std::ios::binary);
  Vocabulary vocabulary;
  if (!vocabulary.read(in, &error)) throw VocabularyError("vocabulary '" + path + "': " + error);
  return vocabulary;
}

}  // namespace slamd
