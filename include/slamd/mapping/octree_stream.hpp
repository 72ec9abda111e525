#pragma once
// Checks of OctoMap's serialised trees, run before OctoMap's own readers see the bytes.
//
// OctoMap's readers trust their input: a node that claims children is followed by them, however
// deep, so a corrupt or hostile stream makes the reader recurse without bound (a stack overflow)
// or allocate a node per two bytes forever. Everything slamd reads from outside (map messages,
// map files given as mapping.load_path) is walked here first, without building anything:
//   - binary streams (.bt bodies, slamd.voxel_map_t): two bytes per node, 2 bits per child,
//     0b11 = the child has children;
//   - full streams (.ot bodies): per node its value (4 bytes for OcTree, 7 for ColorOcTree:
//     log-odds and RGB), then one byte with a bit per existing child.
// A tree has 16 levels below the root, so no node deeper than that may have children, and the
// walk must consume every byte.

#include <cstddef>
#include <cstdint>
#include <string>

namespace slamd {

/// True when `data` is exactly one OcTree::writeBinaryData stream (or empty: an empty map).
bool validateOctreeBinary(const std::uint8_t* data, std::size_t size, std::string* error = nullptr);

/// True when `data` is exactly one full (.ot) node stream whose nodes carry `value_bytes` each.
bool validateOctreeFull(const std::uint8_t* data, std::size_t size, std::size_t value_bytes,
                        std::string* error = nullptr);

/// The header of an OctoMap file (.bt "# Octomap OcTree binary file", .ot "# Octomap OcTree
/// file"), as OctoMap's readers parse it: "id", "size", "res" and "data" lines, '#' comments.
struct OctomapFileHeader {
  bool binary = false;    ///< .bt (binary occupancy) rather than .ot (full)
  std::string tree_type;  ///< "OcTree" or "ColorOcTree"
  double resolution_m = 0.0;
  std::size_t data_offset = 0;  ///< first byte of the node stream
};

/// Parses and checks a whole OctoMap file held in memory: the header (an OcTree or
/// ColorOcTree with a finite resolution in 0.1 mm..100 m) and its node stream. Returns false,
/// with a sentence in *error, for anything OctoMap's reader could choke on.
bool checkOctomapFile(const std::uint8_t* data, std::size_t size, OctomapFileHeader& header,
                      std::string* error = nullptr);

}  // namespace slamd
