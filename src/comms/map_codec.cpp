#include "slamd/comms/map_codec.hpp"

#include <cmath>
#include <limits>
#include <sstream>

namespace slamd {

namespace {

bool fail(std::string* error, const std::string& text) {
  if (error) *error = text;
  return false;
}

bool goodResolution(double resolution_m) {
  return std::isfinite(resolution_m) && resolution_m > 1e-4 && resolution_m < 100.0;
}

}  // namespace

slamd::voxel_map_update_t toMapUpdateMessage(const MapUpdate& update) {
  slamd::voxel_map_update_t message;
  message.utime = update.utime;
  message.resolution = update.resolution_m;
  message.frame_id = update.frame_id;
  message.sequence = update.sequence;
  message.num_voxels = static_cast<std::int32_t>(update.voxels.size());
  message.voxels.resize(update.voxels.size());
  for (std::size_t i = 0; i < update.voxels.size(); ++i) {
    for (int k = 0; k < 3; ++k) message.voxels[i].center[k] = update.voxels[i].center_m[k];
    message.voxels[i].log_odds = update.voxels[i].log_odds;
  }
  return message;
}

std::optional<MapUpdate> fromMapUpdateMessage(const slamd::voxel_map_update_t& message,
                                              std::string* error) {
  if (message.num_voxels < 0 ||
      static_cast<std::size_t>(message.num_voxels) != message.voxels.size()) {
    fail(error, "voxel_map_update_t: num_voxels does not match the voxels");
    return std::nullopt;
  }
  if (!goodResolution(message.resolution)) {
    fail(error, "voxel_map_update_t: resolution " + std::to_string(message.resolution) +
                    " is not a positive finite length");
    return std::nullopt;
  }
  MapUpdate update;
  update.utime = message.utime;
  update.resolution_m = message.resolution;
  update.frame_id = message.frame_id;
  update.sequence = message.sequence;
  update.voxels.reserve(message.voxels.size());
  for (const slamd::voxel_t& voxel : message.voxels) {
    const Eigen::Vector3f center(voxel.center[0], voxel.center[1], voxel.center[2]);
    if (!center.allFinite() || !std::isfinite(voxel.log_odds)) {
      fail(error, "voxel_map_update_t: a voxel has a non-finite centre or log-odds");
      return std::nullopt;
    }
    update.voxels.push_back({center, voxel.log_odds});
  }
  return update;
}

slamd::voxel_map_t toFullMapMessage(const FullMap& map) {
  slamd::voxel_map_t message;
  message.utime = map.utime;
  message.resolution = map.resolution_m;
  message.frame_id = map.frame_id;
  message.update_sequence = map.update_sequence;
  message.num_bytes = static_cast<std::int32_t>(map.data.size());
  message.data.assign(map.data.begin(), map.data.end());
  return message;
}

std::optional<FullMap> fromFullMapMessage(const slamd::voxel_map_t& message, std::string* error) {
  if (message.num_bytes < 0 || static_cast<std::size_t>(message.num_bytes) != message.data.size()) {
    fail(error, "voxel_map_t: num_bytes does not match the data");
    return std::nullopt;
  }
  if (!goodResolution(message.resolution)) {
    fail(error, "voxel_map_t: resolution " + std::to_string(message.resolution) +
                    " is not a positive finite length");
    return std::nullopt;
  }
  if (!validateOctreeBinary(message.data.data(), message.data.size(), error)) return std::nullopt;
  FullMap map;
  map.utime = message.utime;
  map.resolution_m = message.resolution;
  map.frame_id = message.frame_id;
  map.update_sequence = message.update_sequence;
  map.data.assign(message.data.begin(), message.data.end());
  return map;
}

std::unique_ptr<octomap::OcTree> fullMapToOcTree(const FullMap& map, std::string* error) {
  if (!goodResolution(map.resolution_m)) {
    fail(error, "full map: bad resolution");
    return nullptr;
  }
  if (!validateOctreeBinary(map.data.data(), map.data.size(), error)) return nullptr;
  auto tree = std::make_unique<octomap::OcTree>(map.resolution_m);
  if (map.data.empty()) return tree;  // readBinaryData would read a root from nothing
  std::istringstream stream(std::string(map.data.begin(), map.data.end()), std::ios::binary);
  tree->readBinaryData(stream);
  return tree;
}

std::optional<octomap::OcTreeKey> voxelChangeKey(const VoxelChange& voxel,
                                                 const octomap::OcTree& tree) {
  // Checked here, before OctoMap's coordToKey: it converts to int without a range check, so a
  // NaN or a coordinate far outside the tree (found by fuzzing: 2.7e24 m) is undefined
  // behaviour. The tree spans +-resolution * 2^15 around the origin on each axis.
  const double extent_m = tree.getResolution() * 32768.0;
  if (!voxel.center_m.allFinite() || !std::isfinite(voxel.log_odds) ||
      (voxel.center_m.cast<double>().array().abs() >= extent_m).any()) {
    return std::nullopt;
  }
  octomap::OcTreeKey key;
  if (!tree.coordToKeyChecked(
          octomap::point3d(voxel.center_m.x(), voxel.center_m.y(), voxel.center_m.z()), key)) {
    return std::nullopt;
  }
  return key;
}

std::size_t applyMapUpdate(const MapUpdate& update, octomap::OcTree& tree) {
  std::size_t applied = 0;
  for (const VoxelChange& voxel : update.voxels) {
    if (const auto key = voxelChangeKey(voxel, tree)) {
      tree.setNodeValue(*key, voxel.log_odds, true);
      ++applied;
    }
  }
  tree.updateInnerOccupancy();
  return applied;
}

MapReplica::MapReplica(double resolution_m) { resetTree(resolution_m); }

void MapReplica::resetTree(double resolution_m) {
  tree_ = std::make_unique<octomap::OcTree>(resolution_m);
  // Wide clamping so that the publisher's log-odds are stored as sent.
  tree_->setClampingThresMin(0.001);
  tree_->setClampingThresMax(0.999);
}

MapReplica::UpdateResult MapReplica::applyUpdate(const MapUpdate& update) {
  if (!goodResolution(update.resolution_m)) {
    ++rejected_;
    return UpdateResult::kRejected;
  }
  if (std::abs(update.resolution_m - tree_->getResolution()) > 1e-9) {
    if (received_anything_ || tree_->size() > 0) {
      ++rejected_;
      return UpdateResult::kRejected;
    }
    resetTree(update.resolution_m);
  }
  received_anything_ = true;
  if (update.sequence < next_sequence_) {
    ++updates_skipped_;
    return UpdateResult::kAlreadyContained;
  }
  if (synchronised_ && update.sequence > next_sequence_) {
    synchronised_ = false;  // lost messages or a rebuilt map: only a full map can repair this
    ++gaps_;
  }
  if (!synchronised_) {
    ++updates_skipped_;
    return UpdateResult::kWaitingForFullMap;
  }
  applyMapUpdate(update, *tree_);
  next_sequence_ = update.sequence + 1;
  ++updates_applied_;
  return UpdateResult::kApplied;
}

bool FullMapRequestPacer::due(const MapReplica& replica, std::int64_t now_ns, double period_s) {
  if (replica.synchronised()) return false;
  if (last_request_ns_ != 0 && static_cast<double>(now_ns - last_request_ns_) * 1e-9 < period_s) {
    return false;
  }
  last_request_ns_ = now_ns;
  return true;
}

bool MapReplica::applyFullMap(const FullMap& map, std::string* error) {
  std::unique_ptr<octomap::OcTree> tree = fullMapToOcTree(map, error);
  if (!tree) {
    ++rejected_;
    return false;
  }
  tree->setClampingThresMin(0.001);
  tree->setClampingThresMax(0.999);
  tree_ = std::move(tree);
  next_sequence_ = map.update_sequence;
  synchronised_ = true;
  received_anything_ = true;
  return true;
}

}  // namespace slamd
