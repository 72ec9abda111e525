#pragma once
// ViewerModel: what slamd-web knows about a running slamd, kept current from the LCM streams, and
// the messages that bring a browser page up to date (protocol: clients/slamd-web/PROTOCOL.md).
//
// One thread owns it (slamd-web's main thread). It takes decoded messages (poses, keyframes,
// status, vanishing points, map updates and full maps) and produces two kinds of output:
//   - takeBroadcast(): what changed since the previous call, for every connected page (poses
//     batched, voxel changes merged, the newest status/keyframes/vanishing points);
//   - fullState(): everything, for a page that has just connected or fell behind.
// It rides through slamd restarts (the pose or map sequence starting again: every page is told
// to clear) and map gaps (wantsFullMap(): ask slamd for a full map, rate limited).
//
//   ViewerModel model(ViewerModel::Options{});
//   model.onPose(fromPoseMessage(message));
//   ... every 100 ms:
//   for (auto& message : model.takeBroadcast(steadyNowNs())) server.broadcast(message);
//   if (model.wantsFullMap(steadyNowNs())) bus.publishMessage(channels.command, publish_map);

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "slamd/common/pose_estimate.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/status_t.hpp"
#include "slamd/vanishing_point_t.hpp"

namespace slamd::web {

/// One WebSocket message: JSON text, or binary voxel data.
struct OutgoingMessage {
  enum class Kind { kText, kBinary };
  Kind kind = Kind::kText;
  std::string payload;
};

/// Binary voxel frames: a 16-byte header (uint32 kind, uint32 count, float32 resolution_m,
/// uint32 reserved) and `count` 8-byte records (uint16 key x, y, z, uint16 occupied), all
/// little-endian. Keys are OctoMap's finest-level keys: centre = (key - 32768 + 0.5) * resolution.
enum class VoxelFrameKind : std::uint32_t { kReplace = 1, kChanges = 2 };
constexpr std::size_t kVoxelFrameHeaderBytes = 16;
constexpr std::size_t kVoxelRecordBytes = 8;

/// The viewer's own counters (the "viewer" message).
struct ViewerCounters {
  std::int64_t poses_received = 0;
  std::int64_t poses_rejected = 0;  ///< non-finite values
  std::int64_t full_maps = 0;
  std::int64_t full_maps_rejected = 0;
  std::int64_t map_requests = 0;  ///< PUBLISH_MAP commands sent (wantsFullMap)
  std::int64_t restarts = 0;      ///< slamd restarts seen
};

class ViewerModel {
 public:
  struct Options {
    std::string up_axis = "-y";  ///< the world's up axis, as mapping.up_axis spells it
    std::size_t max_trail_poses = 100000;
    double alive_timeout_s = 3.0;       ///< no message for this long: slamd is not running
    double map_request_period_s = 2.0;  ///< at most one full-map request per period
    std::size_t max_voxels = 4000000;   ///< occupied voxels shown at most (memory bound)
  };

  explicit ViewerModel(Options options);

  // Inputs. `now_ns` is the steady clock (steadyNowNs()).
  void onPose(const PoseEstimate& pose, std::int64_t now_ns);
  void onKeyframes(const KeyframeTrajectory& keyframes, std::int64_t now_ns);
  void onStatus(const slamd::status_t& status, std::int64_t now_ns);
  void onVanishingPoint(const slamd::vanishing_point_t& point, std::int64_t now_ns);
  void onMapUpdate(const MapUpdate& update, std::int64_t now_ns);
  /// false (with *error) when the map's bytes are malformed; the copy is kept.
  bool onFullMap(const FullMap& map, std::int64_t now_ns, std::string* error = nullptr);
  /// Counts a message the bus could not decode (shown on the page).
  void onMalformed() { ++malformed_; }

  /// The messages that bring a page that has everything up to the previous call up to date.
  std::vector<OutgoingMessage> takeBroadcast(std::int64_t now_ns);
  /// Every message a newly connected page needs, starting with "hello". Pages that receive this
  /// must also receive every later takeBroadcast().
  std::vector<OutgoingMessage> fullState(std::int64_t now_ns) const;

  /// True when the map copy has a gap that only a full map can heal and no request was made in
  /// the last map_request_period_s; counts the request.
  bool wantsFullMap(std::int64_t now_ns);

  std::size_t trailSize() const { return trail_.size(); }
  std::size_t occupiedVoxels() const { return occupied_keys_.size(); }
  const MapReplica& map() const { return replica_; }
  const ViewerCounters& counters() const { return counters_; }
  void setClientCount(std::size_t clients) { clients_ = clients; }

 private:
  struct TrailPose {
    PoseEstimate pose;
    double sigma_m = 0.0;
  };
  using VoxelKey = std::uint64_t;  ///< OctoMap key, x | y << 16 | z << 32

  void restart(const char* reason);
  void noteAlive(std::int64_t now_ns) { last_message_ns_ = now_ns; }
  bool alive(std::int64_t now_ns) const;
  /// Records a voxel's new occupancy, remembering what pages were last told about it.
  void setOccupied(VoxelKey key, bool occupied);
  /// Rebuilds the occupied set from the replica's tree (after a full map).
  void resyncOccupiedFromTree();

  std::string helloMessage() const;
  std::string posesMessage(const char* type, std::deque<TrailPose>::const_iterator begin,
                           std::deque<TrailPose>::const_iterator end) const;
  std::string keyframesMessage() const;
  std::string statusMessage() const;
  std::string vanishingMessage() const;
  std::string viewerMessage(std::int64_t now_ns) const;
  std::string replaceVoxelsFrame() const;
  std::string changedVoxelsFrame() const;

  Options options_;
  MapReplica replica_;
  std::unordered_set<VoxelKey> occupied_keys_;
  /// Keys changed since the previous broadcast -> occupancy the pages were last told.
  std::unordered_map<VoxelKey, bool> changed_since_broadcast_;
  std::deque<TrailPose> trail_;
  std::size_t trail_poses_broadcast_ = 0;  ///< newest trail_ entries not yet broadcast: size - this
  std::int64_t last_pose_sequence_ = -1;
  std::optional<KeyframeTrajectory> keyframes_;
  std::optional<slamd::status_t> status_;
  std::vector<slamd::vanishing_point_t> vanishing_points_;  ///< of the newest image
  bool keyframes_changed_ = false;
  bool status_changed_ = false;
  bool vanishing_changed_ = false;
  std::vector<std::string> pending_resets_;  ///< reasons, sent before anything else
  std::int64_t last_message_ns_ = 0;
  std::int64_t last_viewer_message_ns_ = 0;
  FullMapRequestPacer map_requests_;
  std::int64_t malformed_ = 0;
  std::size_t clients_ = 0;
  ViewerCounters counters_;
};

}  // namespace slamd::web
