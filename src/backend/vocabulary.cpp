#include "slamd/backend/vocabulary.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <istream>
#include <limits>
#include <map>
#include <ostream>
#include <random>
#include <set>

namespace slamd {

int hammingDistance(const BinaryDescriptor& a, const BinaryDescriptor& b) {
  return __builtin_popcountll(a[0] ^ b[0]) + __builtin_popcountll(a[1] ^ b[1]) +
         __builtin_popcountll(a[2] ^ b[2]) + __builtin_popcountll(a[3] ^ b[3]);
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
BinaryDescriptor majority(const std::vector<BinaryDescriptor>& data, const std::vector<int>& members) {
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
  centres.push_back(data[static_cast<std::size_t>(
      members[std::uniform_int_distribution<int>(0, n - 1)(rng)])]);
  std::vector<double> nearest_sq(static_cast<std::size_t>(n),
                                 std::numeric_limits<double>::infinity());
  while (static_cast<int>(centres.size()) < branching) {
    double total = 0.0;
    for (int i = 0; i < n; ++i) {
      const double d = hammingDistance(data[static_cast<std::size_t>(members[i])], centres.back());
      nearest_sq[static_cast<std::size_t>(i)] = std::min(nearest_sq[static_cast<std::size_t>(i)], d * d);
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
      clusters[static_cast<std::size_t>(assignment[static_cast<std::size_t>(i)])].push_back(members[i]);
    }
    if (!changed && iteration > 0) break;
    for (int c = 0; c < k; ++c) {
      if (!clusters[static_cast<std::size_t>(c)].empty()) {
        centres[static_cast<std::size_t>(c)] = majority(data, clusters[static_cast<std::size_t>(c)]);
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
    vocabulary.idf_[w] = std::log(static_cast<double>(num_images) /
                                  std::max(1, images_with_word[w]));
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

constexpr char kMagic[8] = {'S', 'L', 'V', 'O', 'C', 'A', 'B', '1'};

template <typename T>
void put(std::ostream& out, const T& value) {
  out.write(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <typename T>
bool get(std::istream& in, T& value) {
  return static_cast<bool>(in.read(reinterpret_cast<char*>(&value), sizeof(T)));
}

}  // namespace

void Vocabulary::write(std::ostream& out) const {
  out.write(kMagic, sizeof(kMagic));
  put(out, static_cast<std::int32_t>(nodes_.size()));
  put(out, static_cast<std::int32_t>(num_words_));
  for (const Node& node : nodes_) {
    for (std::uint64_t w : node.centre) put(out, w);
    put(out, static_cast<std::int32_t>(node.word));
    put(out, static_cast<std::int32_t>(node.children.size()));
    for (int child : node.children) put(out, static_cast<std::int32_t>(child));
  }
  for (double v : idf_) put(out, v);
}

bool Vocabulary::read(std::istream& in) {
  char magic[sizeof(kMagic)] = {};
  if (!in.read(magic, sizeof(magic)) || std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
    return false;
  }
  std::int32_t num_nodes = 0;
  std::int32_t num_words = 0;
  if (!get(in, num_nodes) || !get(in, num_words) || num_nodes < 0 || num_words < 0 ||
      num_nodes > 100000000 || num_words > num_nodes) {
    return false;
  }
  std::vector<Node> nodes(static_cast<std::size_t>(num_nodes));
  for (std::size_t index = 0; index < nodes.size(); ++index) {
    Node& node = nodes[index];
    for (std::uint64_t& w : node.centre) {
      if (!get(in, w)) return false;
    }
    std::int32_t word = 0;
    std::int32_t num_children = 0;
    if (!get(in, word) || !get(in, num_children) || word < -1 || word >= num_words ||
        num_children < 0 || num_children > num_nodes) {
      return false;
    }
    node.word = word;
    for (std::int32_t c = 0; c < num_children; ++c) {
      std::int32_t child = 0;
      // Children always follow their parent, so the tree has no cycles.
      if (!get(in, child) || child <= static_cast<std::int32_t>(index) || child >= num_nodes) {
        return false;
      }
      node.children.push_back(child);
    }
    if (node.children.empty() && node.word < 0) return false;
  }
  std::vector<double> idf(static_cast<std::size_t>(num_words));
  for (double& v : idf) {
    if (!get(in, v)) return false;
  }
  nodes_ = std::move(nodes);
  idf_ = std::move(idf);
  num_words_ = num_words;
  return true;
}

}  // namespace slamd
