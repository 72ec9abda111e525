#include "slamd/mapping/octree_stream.hpp"

#include <cmath>
#include <cstring>
#include <sstream>

namespace slamd {

namespace {

constexpr unsigned kTreeDepth = 16;

bool fail(std::string* error, const std::string& text) {
  if (error) *error = text;
  return false;
}

/// One node of a binary stream: two bytes, 2 bits per child.
bool walkBinaryNode(const std::uint8_t* data, std::size_t size, std::size_t& pos, unsigned depth) {
  if (size - pos < 2) return false;
  const std::uint8_t bytes[2] = {data[pos], data[pos + 1]};
  pos += 2;
  for (unsigned child = 0; child < 8; ++child) {
    const unsigned bits = (bytes[child / 4] >> (2 * (child % 4))) & 3u;
    if (bits != 3u) continue;
    // The root is depth 0 and leaves are at depth 16: only nodes above 15 have grandchildren.
    if (depth + 1 >= kTreeDepth) return false;
    if (!walkBinaryNode(data, size, pos, depth + 1)) return false;
  }
  return true;
}

/// One node of a full stream: its value, a child bit mask, then each existing child.
bool walkFullNode(const std::uint8_t* data, std::size_t size, std::size_t value_bytes,
                  std::size_t& pos, unsigned depth) {
  if (size - pos < value_bytes + 1) return false;
  pos += value_bytes;
  const std::uint8_t children = data[pos++];
  if (children != 0 && depth >= kTreeDepth) return false;
  for (unsigned child = 0; child < 8; ++child) {
    if ((children >> child) & 1u) {
      if (!walkFullNode(data, size, value_bytes, pos, depth + 1)) return false;
    }
  }
  return true;
}

}  // namespace

bool validateOctreeBinary(const std::uint8_t* data, std::size_t size, std::string* error) {
  if (size == 0) return true;  // an empty map
  std::size_t pos = 0;
  if (!walkBinaryNode(data, size, pos, 0)) {
    return fail(error, "octree stream is truncated or deeper than 16 levels");
  }
  if (pos != size) {
    return fail(error, "octree stream has " + std::to_string(size - pos) + " trailing bytes");
  }
  return true;
}

bool validateOctreeFull(const std::uint8_t* data, std::size_t size, std::size_t value_bytes,
                        std::string* error) {
  if (size == 0) return true;  // an empty map
  std::size_t pos = 0;
  if (!walkFullNode(data, size, value_bytes, pos, 0)) {
    return fail(error, "octree stream is truncated or deeper than 16 levels");
  }
  if (pos != size) {
    return fail(error, "octree stream has " + std::to_string(size - pos) + " trailing bytes");
  }
  return true;
}

bool checkOctomapFile(const std::uint8_t* data, std::size_t size, OctomapFileHeader& header,
                      std::string* error) {
  static constexpr char kBinaryMagic[] = "# Octomap OcTree binary file";
  static constexpr char kFullMagic[] = "# Octomap OcTree file";
  const auto startsWith = [&](const char* magic) {
    const std::size_t n = std::strlen(magic);
    return size >= n && std::memcmp(data, magic, n) == 0;
  };
  header = OctomapFileHeader{};
  if (startsWith(kBinaryMagic)) {
    header.binary = true;
  } else if (!startsWith(kFullMagic)) {
    return fail(error, "not an OctoMap file (no '# Octomap OcTree' first line)");
  }
  // The header is text, a few lines long; read it as OctoMap does, token by token, from at most
  // the first 4 kB.
  const std::size_t header_limit = std::min<std::size_t>(size, 4096);
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), header_limit));
  std::string token;
  std::getline(in, token);  // the magic line
  bool has_resolution = false;
  bool has_data = false;
  while (!has_data && in >> token) {
    if (token.empty()) continue;
    if (token[0] == '#') {
      std::getline(in, token);
    } else if (token == "id") {
      in >> header.tree_type;
    } else if (token == "res") {
      has_resolution = static_cast<bool>(in >> header.resolution_m);
    } else if (token == "size") {
      std::string ignored;  // OctoMap recounts the nodes after reading
      in >> ignored;
    } else if (token == "data") {
      // The stream starts after the end of this line.
      // (Found by fuzzing: a "data" line without its newline left no valid stream position.)
      std::getline(in, token);
      if (!in.good()) break;
      const std::streamoff offset = in.tellg();
      if (offset < 0 || static_cast<std::size_t>(offset) > size) break;
      header.data_offset = static_cast<std::size_t>(offset);
      has_data = true;
    } else {
      return fail(error, "unknown OctoMap header line '" + token.substr(0, 40) + "'");
    }
  }
  if (!has_data) return fail(error, "OctoMap header has no 'data' line in its first 4 kB");
  if (header.tree_type != "OcTree" && header.tree_type != "ColorOcTree") {
    return fail(error, "OctoMap tree type '" + header.tree_type.substr(0, 40) +
                           "' is not OcTree or ColorOcTree");
  }
  if (!has_resolution || !std::isfinite(header.resolution_m) || header.resolution_m < 1e-4 ||
      header.resolution_m > 100.0) {
    return fail(error, "OctoMap resolution is missing or not in 0.0001..100 m");
  }
  const std::uint8_t* stream = data + header.data_offset;
  const std::size_t stream_size = size - header.data_offset;
  if (header.binary) return validateOctreeBinary(stream, stream_size, error);
  // OcTreeNode: a float log-odds; ColorOcTreeNode: the log-odds and three colour bytes.
  const std::size_t value_bytes = header.tree_type == "OcTree" ? 4 : 7;
  return validateOctreeFull(stream, stream_size, value_bytes, error);
}

}  // namespace slamd
