// Fuzz target: the map codec and map files. The first byte chooses what the rest is:
//   0  a slamd.voxel_map_t message (a full map): decoded, checked, loaded into a replica;
//   1  a slamd.voxel_map_update_t message: decoded, checked, applied to a replica;
//   2  a bare binary octree stream (the body of a full map), built into a tree when valid;
//   3  an OctoMap file (.bt or .ot, as mapping.load_path reads), checked and then loaded by
//      OctoMap's reader when the check passes.

#include <sstream>

#include <octomap/AbstractOcTree.h>
#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>

#include "fuzz_input.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/mapping/octree_stream.hpp"

namespace {

using namespace slamd;

void loadOctomapFile(const std::vector<std::uint8_t>& bytes) {
  OctomapFileHeader header;
  if (!checkOctomapFile(bytes.data(), bytes.size(), header)) return;
  std::istringstream in(std::string(bytes.begin(), bytes.end()), std::ios::binary);
  if (header.binary) {
    octomap::OcTree tree(header.resolution_m);
    tree.readBinary(in);
  } else {
    std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(in));
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz::FuzzInput input(data, size);
  const std::uint8_t kind = input.byte() % 4;
  const std::vector<std::uint8_t> bytes = input.rest();
  switch (kind) {
    case 0:
      if (auto message = decodeMessage<slamd::voxel_map_t>(bytes.data(), bytes.size())) {
        if (auto map = fromFullMapMessage(*message)) {
          MapReplica replica;
          if (replica.applyFullMap(*map)) replica.tree().calcNumNodes();
        }
      }
      break;
    case 1:
      if (auto message = decodeMessage<slamd::voxel_map_update_t>(bytes.data(), bytes.size())) {
        if (auto update = fromMapUpdateMessage(*message)) {
          MapReplica replica;
          replica.applyUpdate(*update);
          replica.applyUpdate(*update);  // the same sequence again: already contained
        }
      }
      break;
    case 2: {
      FullMap map;
      map.resolution_m = 0.05;
      map.data = bytes;
      if (auto tree = fullMapToOcTree(map)) tree->calcNumNodes();
      break;
    }
    case 3:
      loadOctomapFile(bytes);
      break;
  }
  return 0;
}
