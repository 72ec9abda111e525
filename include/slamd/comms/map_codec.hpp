#pragma once
// Conversions between the mapper's outputs and the map messages, and a subscriber's copy of the
// map kept current from them:
//   slamd.voxel_map_update_t <-> MapUpdate     (voxels changed since the previous update)
//   slamd.voxel_map_t        <-> FullMap       (OctoMap binary stream, OcTree::writeBinaryData)
//
// Subscriber usage (slamd-map-save and any other client; one thread owns the replica):
//   MapReplica replica;
//   on SLAMD_MAP_UPDATE: if (auto u = fromMapUpdateMessage(msg, &why)) replica.applyUpdate(*u);
//   on SLAMD_MAP:        if (auto m = fromFullMapMessage(msg, &why))   replica.applyFullMap(*m);
//   replica.tree().writeBinary("map.bt");
// Updates are applied in sequence; a missing sequence number (a lost message, or the publisher
// rebuilding its map) makes the replica wait for the next full map, whose update_sequence says
// which update follows it. Decoding never trusts the bytes: counts, finiteness and the octree
// stream's structure are checked before anything reaches OctoMap.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include <octomap/OcTree.h>

#include "slamd/mapping/map_types.hpp"
#include "slamd/mapping/octree_stream.hpp"  // validateOctreeBinary
#include "slamd/voxel_map_t.hpp"
#include "slamd/voxel_map_update_t.hpp"

namespace slamd {

slamd::voxel_map_update_t toMapUpdateMessage(const MapUpdate& update);
/// nullopt (with a sentence in *error) on inconsistent counts, a non-positive or non-finite
/// resolution, or non-finite voxel values.
std::optional<MapUpdate> fromMapUpdateMessage(const slamd::voxel_map_update_t& message,
                                              std::string* error = nullptr);

slamd::voxel_map_t toFullMapMessage(const FullMap& map);
/// nullopt on inconsistent counts, a bad resolution, or bytes that are not a well-formed OctoMap
/// binary stream (see validateOctreeBinary).
std::optional<FullMap> fromFullMapMessage(const slamd::voxel_map_t& message,
                                          std::string* error = nullptr);

/// Builds an OcTree from a full map (validated first); nullptr with *error on failure.
std::unique_ptr<octomap::OcTree> fullMapToOcTree(const FullMap& map, std::string* error = nullptr);

/// The tree key of an update's voxel; nullopt for non-finite values or a centre outside the
/// tree's extent (such voxels are skipped).
std::optional<octomap::OcTreeKey> voxelChangeKey(const VoxelChange& voxel,
                                                 const octomap::OcTree& tree);

/// Sets each voxel of `update` to its log-odds in `tree` (whose resolution must match);
/// returns the number applied. Voxels outside the tree's extent are skipped.
std::size_t applyMapUpdate(const MapUpdate& update, octomap::OcTree& tree);

/// A subscriber's own copy of the map.
class MapReplica {
 public:
  enum class UpdateResult {
    kApplied,
    kAlreadyContained,   ///< older than the last full map: skipped
    kWaitingForFullMap,  ///< after a gap: skipped until a full map arrives
    kRejected,           ///< resolution differs from the map's
  };

  /// Starts empty at sequence 0, so a subscriber present from the publisher's start needs no
  /// full map. @param resolution_m used until the first message says otherwise, metres.
  explicit MapReplica(double resolution_m = 0.05);

  UpdateResult applyUpdate(const MapUpdate& update);
  /// Replaces the copy (validating the bytes); false with *error when they are malformed.
  bool applyFullMap(const FullMap& map, std::string* error = nullptr);

  const octomap::OcTree& tree() const { return *tree_; }
  bool synchronised() const { return synchronised_; }
  std::int64_t nextSequence() const { return next_sequence_; }
  std::int64_t updatesApplied() const { return updates_applied_; }
  std::int64_t updatesSkipped() const { return updates_skipped_; }
  std::int64_t gaps() const { return gaps_; }
  std::int64_t rejected() const { return rejected_; }

 private:
  void resetTree(double resolution_m);

  std::unique_ptr<octomap::OcTree> tree_;
  bool synchronised_ = true;
  bool received_anything_ = false;
  std::int64_t next_sequence_ = 0;
  std::int64_t updates_applied_ = 0;
  std::int64_t updates_skipped_ = 0;
  std::int64_t gaps_ = 0;
  std::int64_t rejected_ = 0;
};

/// Paces a subscriber's requests for a full map (PUBLISH_MAP on the command channel) while its
/// replica waits for one after a gap: the first at once, then at most one per period. Kept apart
/// from the replica so that a replica started afresh (the publisher restarted) keeps the pace.
class FullMapRequestPacer {
 public:
  /// True when a request should go out now (and counts it as sent at now_ns).
  bool due(const MapReplica& replica, std::int64_t now_ns, double period_s);

 private:
  std::int64_t last_request_ns_ = 0;  ///< 0: none yet
};

}  // namespace slamd
