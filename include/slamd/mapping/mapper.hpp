#pragma once
// Mapper: posed depth frames -> probabilistic 3D voxel map (OctoMap), with incremental updates,
// full maps, a 2D projection, exports, crash-safe persistence and re-integration after pose
// corrections.
//
// Usage (the mapping thread owns the Mapper; it has no threads, locks or LCM inside):
//   Mapper mapper(MappingConfig::load(config));
//   for each frame with its pose:
//     IntegrationResult r = mapper.integrate(*frame, T_world_camera, keyframe_id_or_nullopt);
//     MapperOutputs out = mapper.poll(frame->utime);   // due updates / full map / snapshot
//     if (out.update) publish(toMapUpdateMessage(*out.update));    // slamd/comms/map_codec.hpp
//     if (out.full_map) publish(toFullMapMessage(*out.full_map));
//   on PUBLISH_MAP: mapper.requestFullMap();  on SAVE_MAP / shutdown: mapper.saveMaps(prefix);
//   with a back end: keyframes go in through the queue, a part at a time:
//     mapper.addKeyframe(*frame, T_world_camera, keyframe_id);
//     on corrected keyframe poses: mapper.correctKeyframePoses(poses);
//     on every mapping cycle: mapper.catchUp(budget_s);  // bounded time per call
//   sessions (keyframe_cloud_io.hpp) save the map with its keyframe clouds, at the same moment:
//     mapper.saveMap(dir + "/map.ot");
//     writeKeyframeCloudRecords(clouds_path, mapper.keyframeCloudRecords());
//   and a later run loads both, the map first:
//     mapper.loadMap(dir + "/map.ot");
//     readKeyframeCloudRecords(clouds_path, records);
//     mapper.restoreKeyframeClouds(std::move(records));
//
// Per frame: depth (CV_32FC1 metres, NaN = none) -> camera-frame cloud without NaN, inf, zero,
// negative or out-of-range depths -> voxel-grid filter (camera frame) -> transform by
// T_world_camera -> rays from the sensor origin (the camera centre, world frame) to each point:
// voxels along a ray are updated as free (prob_miss), the endpoint voxel as occupied (prob_hit);
// rays longer than max_range_m clear free space up to max_range_m only. Bad input (wrong image
// type or size, invalid intrinsics, non-finite or non-rigid poses, points outside the map's
// extent) never reaches OctoMap: it is rejected and counted in stats().
//
// Keyframes that follow corrections (config.keep_keyframe_clouds): a keyframe's filtered cloud is
// kept, sorted by image row and cut into parts of keyframe_step_points points (bands of the
// image), and each part's contribution to the map (the log-odds of every voxel its rays crossed
// or ended in, each voxel counted once per part) can be taken out exactly by adding the negated
// updates at the pose it went in at. A correction therefore moves only the keyframes it moves, a
// part at a time within a time budget per call, and the map never re-integrates its history. For
// the subtraction to be exact the log-odds are not clamped in this mode (clamp_min and clamp_max
// are not applied): the map's value in a voxel is the sum of the contributions of the keyframes
// that saw it, and culled keyframes are taken out. A voxel whose contributions are all taken out is
// deleted (unknown again).
//
// Frames: T_world_camera maps camera optical-frame points (x right, y down, z forward, metres)
// into the map frame (config.frame_id). Every coordinate the Mapper returns is in the map frame.

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>

#include "slamd/common/memory_pressure.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/mapping/keyframe_cloud_io.hpp"
#include "slamd/mapping/map_io.hpp"
#include "slamd/mapping/map_types.hpp"
#include "slamd/mapping/mapping_config.hpp"
#include "slamd/mapping/point_cloud.hpp"

namespace slamd {

enum class IntegrationStatus {
  kOk,
  kBadFrame,  ///< depth not CV_32FC1, size differs from the intrinsics, or invalid intrinsics
  kBadPose,   ///< non-finite pose, a rotation that is not orthonormal, or an origin off the map
  kNoPoints,  ///< no valid depth left after filtering (the map is unchanged)
};

const char* toString(IntegrationStatus status);

/// What one integrate() call did.
struct IntegrationResult {
  IntegrationStatus status = IntegrationStatus::kOk;
  std::string error;                ///< a sentence when status != kOk
  DepthCloudStats depth;            ///< per-pixel accounting of the depth image
  std::size_t points_filtered = 0;  ///< points after the voxel-grid filter
  std::size_t points_off_map = 0;   ///< points outside the OcTree's addressable extent
  std::size_t free_voxels = 0;      ///< distinct voxels updated as free
  std::size_t occupied_voxels = 0;  ///< distinct voxels updated as occupied
  bool keyframe_cloud_kept = false;
  double cloud_ms = 0.0;    ///< depth -> cloud
  double filter_ms = 0.0;   ///< voxel-grid filter
  double insert_ms = 0.0;   ///< transform + ray casting + OcTree update
  double raycast_ms = 0.0;  ///< of insert_ms: rays and the frame's distinct voxels
  double update_ms = 0.0;   ///< of insert_ms: OcTree updates (and colours)
};

/// Totals since construction (the daemon publishes them on the status channel).
struct MapperStats {
  std::int64_t frames_integrated = 0;
  std::int64_t frames_bad_frame = 0;
  std::int64_t frames_bad_pose = 0;
  std::int64_t frames_no_points = 0;
  std::int64_t depth_nan = 0;
  std::int64_t depth_infinite = 0;
  std::int64_t depth_zero = 0;
  std::int64_t depth_negative = 0;
  std::int64_t depth_out_of_range = 0;  ///< too near or too far
  std::int64_t points_off_map = 0;
  std::int64_t points_inserted = 0;  ///< endpoints after filtering, summed over frames
  std::int64_t updates_published = 0;
  std::int64_t full_maps_published = 0;
  std::int64_t snapshots_written = 0;
  std::int64_t snapshot_failures = 0;
  std::int64_t snapshot_retries = 0;  ///< snapshots written early because the previous one failed
  std::int64_t keyframe_clouds = 0;   ///< currently kept
  std::int64_t keyframe_clouds_refused = 0;   ///< not kept: the cloud budget, or memory pressure
  std::int64_t keyframe_clouds_released = 0;  ///< dropped under memory pressure, left in the map
  std::int64_t keyframe_clouds_invalid = 0;  ///< records restoreKeyframeClouds() refused as invalid
  std::int64_t keyframe_cloud_bytes = 0;
  std::int64_t keyframes_moved = 0;        ///< contributions moved to corrected poses
  std::int64_t keyframes_taken_out = 0;    ///< contributions removed (forgotten keyframes)
  std::int64_t corrections_caught_up = 0;  ///< times every queued keyframe had been moved
  std::int64_t far_map_coarsenings = 0;    ///< coarsenFarMap() calls that merged anything
  std::int64_t far_map_blocks_merged = 0;  ///< blocks of 8 voxels merged into one, summed
};

/// Result of a save or load.
struct MapFileResult {
  bool ok = false;
  std::string path;
  std::string error;  ///< a sentence when !ok
  double seconds = 0.0;
};

/// What poll() found due.
struct MapperOutputs {
  std::optional<MapUpdate> update;
  std::optional<FullMap> full_map;
  std::optional<MapFileResult> snapshot;
};

/// Leaves of the OcTree (a pruned block counts once) and how many of them are occupied.
struct VoxelCounts {
  std::size_t leaves = 0;
  std::size_t occupied = 0;
};

/// Result of correctKeyframePoses().
struct KeyframeCorrectionResult {
  std::size_t keyframes_to_move = 0;  ///< queued: some point would move by over half a voxel
  std::size_t unknown_ids = 0;        ///< ids in the request without a kept cloud, or bad poses
};

/// Result of coarsenFarMap().
struct CoarsenResult {
  std::size_t blocks_merged = 0;  ///< nodes whose 8 children became one voxel of their size
  std::size_t nodes_removed = 0;  ///< OcTree nodes freed
  double seconds = 0.0;
};

/// Result of catchUp().
struct CatchUpResult {
  std::size_t steps = 0;            ///< parts put in or taken out, keyframes forgotten
  std::size_t keyframes_added = 0;  ///< new keyframes now wholly in the map
  std::size_t keyframes_moved = 0;  ///< keyframes now wholly in at their corrected poses
  std::size_t keyframes_left = 0;   ///< still queued (the budget ran out)
  bool caught_up = false;           ///< this call did the last queued step
  double seconds = 0.0;
};

class Mapper {
 public:
  /// Throws std::invalid_argument when config.validationError() is not empty. Loads
  /// config.load_path when set (throws std::runtime_error when it cannot be read).
  explicit Mapper(const MappingConfig& config);
  ~Mapper();
  Mapper(const Mapper&) = delete;
  Mapper& operator=(const Mapper&) = delete;

  /// Integrates one frame. @param T_world_camera pose of the camera optical frame in the map
  /// frame (metres). @param keyframe_id when set (and keep_keyframe_clouds), the filtered
  /// camera-frame cloud is kept under this id so that corrections can move it; an existing id is
  /// replaced (its earlier contribution taken out first).
  IntegrationResult integrate(const RgbdFrame& frame, const SE3& T_world_camera,
                              std::optional<std::int64_t> keyframe_id = std::nullopt);
  /// A keyframe (keep_keyframe_clouds): its filtered cloud is kept and queued; catchUp() puts it
  /// in, a part at a time, before any move. A cloud the memory budget refuses goes in at once and
  /// cannot be moved (as without keep_keyframe_clouds).
  IntegrationResult addKeyframe(const RgbdFrame& frame, const SE3& T_world_camera,
                                std::int64_t keyframe_id);
  /// addKeyframe() for a keyframe whose pose is not yet in the map's frame (a run not yet
  /// localised in a loaded session): kept and queued the same way, but a cloud that cannot be
  /// kept is dropped (result.keyframe_cloud_kept false) instead of going in at once. The caller
  /// runs catchUp() only once correctKeyframePoses() has given it a pose in the map's frame.
  IntegrationResult holdKeyframe(const RgbdFrame& frame, const SE3& T_world_camera,
                                 std::int64_t keyframe_id);

  /// Integrates a cloud already in the camera frame (no depth conversion, no filter).
  /// @param cloud_camera points in the camera optical frame, metres (non-finite points dropped).
  IntegrationResult integrateCloud(const PointCloud& cloud_camera, const SE3& T_world_camera,
                                   Utime utime,
                                   std::optional<std::int64_t> keyframe_id = std::nullopt);

  // --- outputs --------------------------------------------------------------------------------
  /// Returns the outputs due at `now` (message time, microseconds): an update every
  /// 1/update_rate_hz, a full map every full_map_period_s or after requestFullMap(), a snapshot
  /// every snapshot_period_s (after a failed one, retried after 1, 2, 4, ... s up to the period).
  /// An update is always emitted before a full map so that the map's
  /// update_sequence covers it. Empty updates are not emitted.
  MapperOutputs poll(Utime now);
  /// The changes since the previous update (possibly none); advances the sequence when it holds
  /// voxels (an empty update is not sent, so it takes no number).
  MapUpdate takeUpdate();
  /// The whole map now. Does not advance the update sequence.
  FullMap fullMap();
  /// Makes the next poll() emit a full map (the PUBLISH_MAP command).
  void requestFullMap() { full_map_requested_ = true; }
  bool fullMapRequested() const { return full_map_requested_; }
  /// 2D projection of the configured height band (see OccupancyGrid2D).
  OccupancyGrid2D projectToGrid();
  OccupancyGrid2D projectToGrid(UpAxis up_axis, double min_height_m, double max_height_m);
  /// Centres of every occupied finest voxel (map frame, metres) with voxel colours (white when
  /// the map has no colour).
  PointCloud occupiedCloud();
  /// Writes occupiedCloud() as PLY, atomically.
  MapFileResult exportOccupiedPly(const std::string& path, PlyFormat format);
  /// Writes the kept keyframe clouds, moved by their poses into the map frame, concatenated and
  /// voxel-filtered at voxel_m (metres; 0 = no filter), as a coloured PLY (paper 004's model).
  MapFileResult exportKeyframeCloudPly(const std::string& path, double voxel_m, PlyFormat format);

  // --- persistence ------------------------------------------------------------------------------
  /// Saves the map crash-safely: .bt (maximum likelihood, OcTree::writeBinary format) or .ot
  /// (full log-odds, and colour for a ColorOcTree), chosen by the extension.
  MapFileResult saveMap(const std::string& path);
  /// Saves <prefix>.bt and <prefix>.ot; the result of the first failure, else of the .ot.
  MapFileResult saveMaps(const std::string& prefix);
  /// Writes the snapshot now (config.snapshot_path); fails when no path is configured.
  MapFileResult saveSnapshot();
  /// Replaces the map by a saved .bt or .ot and continues mapping on it. The file's resolution
  /// and tree type (OcTree or ColorOcTree) are adopted; kept keyframe clouds are forgotten
  /// (restoreKeyframeClouds() brings back those saved with the map).
  /// Subscribers resynchronise from the next full map.
  MapFileResult loadMap(const std::string& path);

  // --- following corrections -----------------------------------------------------------------
  /// Sets the corrected pose (T_world_camera, map frame) of kept keyframes. A keyframe whose
  /// cloud would move by more than half a voxel (translation plus rotation angle times its
  /// farthest point's distance) is queued for catchUp(); the others stay where they are.
  /// Corrections may come faster than the queue empties: each keyframe moves once, to its newest
  /// pose.
  KeyframeCorrectionResult correctKeyframePoses(
      const std::vector<std::pair<std::int64_t, SE3>>& keyframe_poses);
  /// Works through the queue: keyframes to forget and new keyframes first, then keyframes to
  /// move, farthest move first. A step takes one part of a keyframe out (at the pose it went in
  /// at) or puts one in (at its corrected pose), about 1/parts of a frame's ray casting. With
  /// budget_s > 0, does at least one step and starts no other that would not fit (judged by the
  /// last step's time); with budget_s <= 0, nothing. Once the queue is empty, if voxels became
  /// unknown (which updates cannot say), subscribers resynchronise from the full map the next
  /// poll() emits.
  CatchUpResult catchUp(double budget_s);
  std::size_t keyframesQueued() const { return keyframes_queued_.size(); }
  /// How long catchUp()'s last step took (0 before the first): what the next one will cost.
  double lastStepSeconds() const { return last_step_s_; }
  /// Forgets a keyframe (culled by the back end): its contribution is taken out of the map and
  /// its cloud dropped.
  void forgetKeyframe(std::int64_t keyframe_id);
  /// forgetKeyframe() in catchUp()'s steps, before any move.
  void forgetKeyframeInSteps(std::int64_t keyframe_id);
  /// Memory pressure (common/memory_pressure.hpp): from kNear on, new keyframe clouds are not
  /// kept (they go in at once, as when the cloud budget refuses them).
  void setMemoryPressure(MemoryPressure pressure) { memory_pressure_ = pressure; }
  /// Makes the map coarser away from `near_point_m` (map frame, metres; the camera), to save
  /// memory (OcTree nodes) under memory pressure. In every block of 2x2x2 voxels, up to
  /// config.coarse_far_levels levels up from the finest, that lies wholly farther than
  /// config.coarse_far_radius_m from the point, the 8 voxels become one of the block's size:
  /// occupied (the largest log-odds, the average colour) when any of them was occupied, free
  /// when all 8 were known and free; a block where free voxels meet unknown ones stays as it is,
  /// so that no unknown space becomes free. Blocks that a kept keyframe's rays reached at the
  /// pose it is in the map at are left alone, so that taking it out stays exact. Later
  /// measurements refine a merged block again (OctoMap expands it). Subscribers resynchronise
  /// from the next full map.
  CoarsenResult coarsenFarMap(const Eigen::Vector3d& near_point_m);
  /// Drops the kept clouds of all but the newest `keep_newest` keyframes (oldest first; only
  /// clouds wholly in the map with nothing queued). Their part of the map stays, but no later
  /// correction can move or take it out. Returns how many were dropped.
  std::size_t releaseKeyframeClouds(std::size_t keep_newest);
  /// Ids of the kept keyframe clouds (forgotten in steps or not yet), in increasing order.
  std::vector<std::int64_t> keptKeyframeIds() const;
  /// Every kept keyframe cloud (not those being forgotten: what of them is still in the map stays
  /// there after a restore, as a released cloud's part does), in id order, as it stands in the
  /// map: a keyframe partway through a move has its parts still in at the pose they went in at,
  /// and its correction is not recorded. Copies every cloud (keyframe_cloud_bytes).
  std::vector<KeyframeCloudRecord> keyframeCloudRecords() const;
  /// After loadMap() of the map these clouds went into (a session's map.ot with the records taken
  /// when it was saved): they are kept again, as if this mapper had integrated them, so that
  /// correctKeyframePoses() and forgetKeyframe() can move them or take them out exactly. Each
  /// keyframe's newest pose is its T_world_camera_in_map (nothing is queued to move); parts not
  /// yet in the map are queued for catchUp(), to go in at that pose. Records are taken in order.
  /// Not kept: a record the cloud budget or memory pressure refuses (keyframe_clouds_refused), an
  /// invalid one (keyframe_clouds_invalid): a pose that is not a finite rigid transform or whose
  /// origin is off the map, no points, a point not finite or over 1e6 m away, colours that are
  /// neither none nor one per point, part_points 0, parts_in_map outside 0 .. parts, an id kept
  /// already (the first record of an id wins). Without keep_keyframe_clouds nothing is kept.
  /// Returns how many were kept.
  std::size_t restoreKeyframeClouds(std::vector<KeyframeCloudRecord> records);
  /// Empties the map (the RESET command) and forgets every keyframe cloud.
  void reset();

  // --- access ---------------------------------------------------------------------------------
  const MappingConfig& config() const { return config_; }
  const MapperStats& stats() const { return stats_; }
  bool hasColor() const { return color_tree_ != nullptr; }
  double resolution() const;
  /// The OcTree (null when the map has colour) or the ColorOcTree (null otherwise). Inner nodes
  /// are brought up to date first. Read only; the mapping thread owns them.
  const octomap::OcTree* ocTree();
  const octomap::ColorOcTree* colorOcTree();
  /// Finest voxel counts of the current map, and the OcTree's memory use in bytes. Each walks
  /// the whole tree.
  std::size_t numLeafNodes() const;
  VoxelCounts countVoxels() const;
  std::size_t memoryBytes() const;
  /// Occupancy at a point (map frame, metres): -1 unknown, 0 free, 1 occupied.
  int occupancyAt(const Eigen::Vector3d& point_m) const;
  /// The sequence number the next update will carry.
  std::int64_t nextUpdateSequence() const { return next_update_sequence_; }
  Utime latestUtime() const { return latest_utime_; }

 private:
  struct KeyframeCloud {
    PointCloud cloud_camera;                      ///< sorted by elevation (image row)
    SE3 T_world_camera = SE3::Identity();         ///< newest pose (corrected)
    SE3 T_world_camera_in_map = SE3::Identity();  ///< the pose its parts in the map went in at
    std::size_t part_points = 1;
    int parts = 1;
    int parts_in_map = 0;           ///< parts 0 .. parts_in_map - 1 are in the map
    bool to_move = false;           ///< its parts come out, then go in at T_world_camera
    bool moving = false;            ///< counted as moved once it is wholly in again
    bool to_forget = false;         ///< forgetKeyframeInSteps() was called
    double farthest_point_m = 0.0;  ///< lever arm for rotations
    Utime utime = 0;
  };
  enum class Contribution { kPutIn, kTakeOut };
  struct Scratch;

  IntegrationResult insertCameraCloud(const PointCloud& cloud_camera, const SE3& T_world_camera,
                                      IntegrationResult result,
                                      Contribution contribution = Contribution::kPutIn);
  template <typename Tree>
  void insertIntoTree(Tree& tree, const octomap::point3d& origin, const PointCloud& cloud_camera,
                      Contribution contribution, IntegrationResult& result);
  /// What becomes of a keyframe's cloud: put in now, queued for catchUp() (put in at once when
  /// it cannot be kept), or queued (dropped when it cannot be kept).
  enum class KeyframeInsertion { kNow, kQueued, kQueuedOrDropped };
  IntegrationResult integrateFrame(const RgbdFrame& frame, const SE3& T_world_camera,
                                   std::optional<std::int64_t> keyframe_id,
                                   KeyframeInsertion insertion);
  /// Integrates filtered_, or keeps it as a keyframe (see KeyframeInsertion).
  IntegrationResult insertFiltered(IntegrationResult result, const SE3& T_world_camera,
                                   std::optional<std::int64_t> keyframe_id, Utime utime,
                                   KeyframeInsertion insertion);
  /// True (and counted) when the sensor origin is off the map or the cloud is empty.
  bool rejectUninsertable(const PointCloud& cloud_camera, const SE3& T_world_camera,
                          IntegrationResult& result);
  /// Puts one part of a kept keyframe in, or takes it out, at T_world_camera_in_map (map
  /// statistics unchanged).
  void putPart(const KeyframeCloud& keyframe, int part, Contribution contribution);
  /// One step of catchUp() on a keyframe; true when it is done with it.
  bool keyframeStep(std::int64_t id, CatchUpResult& result);
  void queueKeyframe(double priority, std::int64_t id);
  void eraseKeyframe(std::map<std::int64_t, KeyframeCloud>::iterator it);
  bool rejectBadPose(const SE3& T_world_camera, IntegrationResult& result);
  void makeEmptyTree(double resolution_m, bool color);
  void configureTree();
  void ensureInnerOccupancy();
  void afterMapReplaced();
  /// Skips an update sequence number and requests a full map (subscribers resynchronise).
  void requestResynchronisation();
  void forgetKeyframeClouds();
  /// True when a cloud of `bytes` fits the budget (after `freed_bytes` of a cloud it replaces) and
  /// memory pressure allows it; otherwise false, counted in keyframe_clouds_refused.
  bool admitKeyframeCloud(std::int64_t bytes, std::int64_t freed_bytes);
  /// False for an invalid record (see restoreKeyframeClouds()).
  bool isRestorable(const KeyframeCloudRecord& record) const;
  bool originOnMap(const SE3& T_world_camera) const;
  bool keepKeyframe(std::int64_t id, const PointCloud& cloud, const SE3& T_world_camera,
                    Utime utime);
  template <typename Function>
  decltype(auto) withTree(Function&& function);
  template <typename Function>
  decltype(auto) withTree(Function&& function) const;

  MappingConfig config_;
  std::unique_ptr<octomap::OcTree> tree_;
  std::unique_ptr<octomap::ColorOcTree> color_tree_;
  std::unique_ptr<Scratch> scratch_;
  VoxelGridFilter voxel_filter_;
  PointCloud cloud_;
  PointCloud filtered_;
  std::map<std::int64_t, KeyframeCloud> keyframes_;
  /// Keyframes with steps to do, by (priority, id): the back is done first. Priority: infinite
  /// for keyframes to forget, new ones and ones partly in the map; otherwise how far they move.
  std::vector<std::pair<double, std::int64_t>> keyframes_queued_;
  PointCloud part_;              ///< scratch: one part of a kept cloud
  double last_step_s_ = 0.0;     ///< how long catchUp()'s last step took
  bool voxels_deleted_ = false;  ///< since the last full map request
  MemoryPressure memory_pressure_ = MemoryPressure::kNone;
  MapperStats stats_;
  bool inner_dirty_ = false;
  int frames_since_prune_ = 0;
  bool full_map_requested_ = false;
  std::int64_t next_update_sequence_ = 0;
  Utime latest_utime_ = 0;
  std::optional<Utime> last_update_time_;
  std::optional<Utime> last_full_map_time_;
  std::optional<Utime> last_snapshot_time_;
  static constexpr double kFirstSnapshotRetryDelayS = 1.0;
  std::optional<Utime> snapshot_retry_at_;  ///< set while the last snapshot failed
  double snapshot_retry_delay_s_ = kFirstSnapshotRetryDelayS;
};

}  // namespace slamd
