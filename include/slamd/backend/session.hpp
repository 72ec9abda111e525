#pragma once
// Session files: what a later run needs to localise in a map built earlier and to extend it
// (--session-out DIR, --session-in DIR, the SAVE_SESSION command, slamd-session-info).
//
// Layout of a session folder DIR:
//   DIR/CURRENT                   one line: the name of the complete generation to read
//   DIR/generation-000007/        one complete save (older generations are removed after a save)
//     manifest.txt                format version, creation time, camera, summary counts, and
//                                 every other file of the generation with its size and checksum
//     keyframes.bin               keyframes: poses, features, descriptors, 3D points
//     graph.bin                   the back end's pose graph and bookkeeping (BackendSnapshot)
//     vocabulary.voc              the place-recognition vocabulary (Vocabulary::write)
//     map.ot                      the OctoMap (full tree with log-odds), when there is a map
//     keyframe_clouds.bin         the mapper's keyframe clouds that went into map.ot, when kept
//     config.yaml                 the configuration the session was made with (effectiveYaml)
//
// Saving is atomic: a save writes a new generation folder, fsyncs every file and the folder, then
// replaces CURRENT with writeFileAtomically(). A crash or kill -9 at any moment leaves CURRENT
// naming either the previous complete generation or the new complete one; an unfinished
// generation folder is removed by the next save. Reading verifies the format version, every
// file's size and FNV-1a checksum, and the consistency of the graph (every edge and culled
// keyframe names a keyframe that exists) before anything is used; a refusal throws SessionError
// naming the file and the problem, and never crashes on arbitrary bytes.
//
// Formats (kSessionFormatVersion):
// - manifest.txt: text lines; the first `slamd-session <version>`, then `key value` lines
//   (created_utime, created_by, camera_*, the summary counts, keyframe_min_m/max_m and
//   map_min_m/max_m as "x y z"), then one `file <name> <bytes> <fnv1a64 as 16 hex digits>` line
//   per file, and last `checksum <16 hex digits>`: FNV-1a of every byte before that line.
// - keyframes.bin and graph.bin: little-endian binary, the magic "SLAMDKFS" / "SLAMDGRF", the
//   format version (uint32), then counts (uint64) each followed by its records; poses as the
//   rotation matrix (row-major) and translation, 12 doubles; information matrices as 36 doubles.
//   Keyframe records: id, segment, utime, frame_sequence, pose, intrinsics, median depth,
//   num_with_depth, keypoints, descriptors (rows, cols, OpenCV type, the elements), pixels,
//   points (NaN = no depth), scales, inverse-depth gradients.
//   Version 2 adds, last in graph.bin, the keyframe pairs that saw each other (views); a
//   version 1 session loads without them.
// Every count is checked against the bytes that remain before anything is allocated.
//
// A snapshot is consistent (SessionWriter refuses to save, and a reader to load, one that is not)
// when: ids are unique and non-negative; the nodes are exactly the keyframes; poses are finite
// rigid transforms and information matrices finite; every edge joins two different nodes and has
// a known kind; a culled keyframe is not a node and its anchor is a node or another culled
// keyframe whose chain of anchors ends at a node; a record names a keyframe or culled keyframe;
// segment_parents names each segment once and has no cycle (a segment may be its own parent);
// a view joins two different nodes, lower id first, and appears once;
// next_keyframe_id is above every keyframe id and next_segment above every segment; per keyframe
// the pixels and points have one entry per keypoint, descriptors one row per keypoint (or none),
// scale and inverse_depth_gradient one entry per keypoint or none, the intrinsics are valid
// (CameraIntrinsics::validationError) and median depth and num_with_depth in range.
//
// Usage (one thread at a time; the daemon saves from its control thread once the pipeline has
// stopped, or through the owning threads for SAVE_SESSION):
//   SessionWriter writer(dir);                     // creates DIR and a new generation folder
//   writer.writeBackend(backend.snapshot());        // keyframes.bin, graph.bin
//   writer.writeVocabulary(*vocabulary);
//   mapper.saveMap(writer.pathFor(kSessionMapFile)); writer.addFile(kSessionMapFile);
//   writer.writeText(kSessionConfigFile, config.effectiveYaml());
//   writer.commit(info);                           // manifest.txt, then CURRENT
//
//   Session session = loadSession(dir);            // throws SessionError
//   backend.restore(session.backend, mode);  mapper.loadMap(session.map_path);

#include <cstdint>
#include <functional>
#include <iosfwd>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "slamd/backend/pose_graph.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/common/time.hpp"
#include "slamd/tracking/keyframe.hpp"

namespace slamd {

/// Version of the session layout and of keyframes.bin / graph.bin. A reader refuses a session
/// with a newer version (made by a newer slamd) and one older than it can read.
inline constexpr std::uint32_t kSessionFormatVersion = 2;
/// The oldest version this slamd reads.
inline constexpr std::uint32_t kSessionOldestReadableVersion = 1;

inline constexpr const char* kSessionCurrentFile = "CURRENT";
inline constexpr const char* kSessionManifestFile = "manifest.txt";
inline constexpr const char* kSessionKeyframesFile = "keyframes.bin";
inline constexpr const char* kSessionGraphFile = "graph.bin";
inline constexpr const char* kSessionVocabularyFile = "vocabulary.voc";
inline constexpr const char* kSessionMapFile = "map.ot";
/// The mapper's kept keyframe clouds (down-sampled, camera frame) with the poses they went into
/// map.ot at (written and read by the mapping side: writeKeyframeCloudRecords), when kept.
inline constexpr const char* kSessionKeyframeCloudsFile = "keyframe_clouds.bin";
inline constexpr const char* kSessionConfigFile = "config.yaml";

/// A keyframe the back end merged into another (culling): it is kept as an offset only.
struct CulledKeyframeRecord {
  std::int64_t id = -1;
  std::int64_t anchor_id = -1;                  ///< the keyframe it was merged into
  SE3 T_anchor_keyframe = SE3::Identity();      ///< metres
  Matrix6d information = Matrix6d::Identity();  ///< of T_anchor_keyframe
};

/// Per keyframe (culled ones included): its tracking segment and odometry path length.
struct KeyframeRecord {
  std::int64_t id = -1;
  std::int64_t segment = 0;
  double path_length_m = 0.0;  ///< odometry path from the first keyframe of its segment
};

/// Everything the Backend needs to continue from where it was (Backend::snapshot / restore).
struct BackendSnapshot {
  /// The keyframes in the graph (not the culled ones), in the order they were added, without
  /// images: id, segment, utime, frame_sequence, odometry T_world_camera, intrinsics, features
  /// (keypoints, descriptors, undistorted pixels, 3D points, scales, inverse-depth gradients,
  /// num_with_depth) and median depth. features.gray and features.align_gray are not saved.
  std::vector<KeyframePtr> keyframes;
  /// Graph nodes in the order they were added: id, optimised T_world_camera, fixed.
  struct Node {
    std::int64_t id = -1;
    SE3 T_world_camera = SE3::Identity();
    bool fixed = false;
  };
  std::vector<Node> nodes;
  std::vector<PoseGraphEdge> edges;  ///< in the graph's order
  std::vector<CulledKeyframeRecord> culled;
  std::vector<KeyframeRecord> records;
  /// Joined tracking segments (union-find parent links: segment -> parent).
  std::vector<std::pair<std::int64_t, std::int64_t>> segment_parents;
  /// Pairs of keyframes (graph nodes, lower id first, each pair once) that a verified match
  /// showed seeing each other: the views the culling of earlier keyframes counts.
  std::vector<std::pair<std::int64_t, std::int64_t>> views;
  std::int64_t first_segment = 0;     ///< the segment whose map every other joins
  std::int64_t next_keyframe_id = 0;  ///< one above every keyframe id used
  std::int64_t next_segment = 0;      ///< one above every segment used
  std::int64_t num_loops = 0;
  std::int64_t num_local_edges = 0;
  std::int64_t num_relocalizations = 0;
};

/// Summary counts and provenance written to the manifest (slamd-session-info prints them without
/// reading the big files).
struct SessionInfo {
  std::uint32_t format_version = kSessionFormatVersion;
  Utime created_utime = 0;  ///< wall-clock time of the save
  std::string created_by;   ///< e.g. "slamd 0.9.0"
  std::string generation;   ///< the generation folder's name
  CameraIntrinsics camera;  ///< the camera the session was made with (after any resizing)
  std::int64_t keyframes = 0;
  std::int64_t culled_keyframes = 0;
  std::int64_t landmarks = 0;  ///< keyframe features with a 3D point
  std::int64_t edges = 0;
  std::int64_t segments = 0;
  std::int64_t loops = 0;
  std::int64_t map_voxels = 0;  ///< leaves of the OctoMap (0 without a map)
  /// Axis-aligned extent of the keyframe positions (metres, the session's world frame).
  Eigen::Vector3d keyframe_min_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d keyframe_max_m = Eigen::Vector3d::Zero();
  /// Axis-aligned extent of the map (metres; zero without a map).
  Eigen::Vector3d map_min_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d map_max_m = Eigen::Vector3d::Zero();
  /// The files of the generation with their sizes (bytes), manifest excluded (filled by
  /// SessionWriter::commit and by the readers).
  std::vector<std::pair<std::string, std::uint64_t>> files;
};

/// A session that cannot be written or read; the message names the file and the problem.
class SessionError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A loaded session.
struct Session {
  std::string dir;              ///< the session folder given
  std::string generation_path;  ///< the generation folder read
  SessionInfo info;
  BackendSnapshot backend;
  std::shared_ptr<const Vocabulary> vocabulary;
  std::string map_path;  ///< path of map.ot, empty when the session has no map
  /// Path of keyframe_clouds.bin (verified, not parsed), empty when the session has none.
  std::string keyframe_clouds_path;
  std::string config_yaml;  ///< config.yaml's text
};

/// Writes one generation of a session folder (see the file comment).
class SessionWriter {
 public:
  /// Creates `dir` when missing, removes unfinished generation folders (not named by CURRENT)
  /// and creates the next generation folder. Throws SessionError.
  explicit SessionWriter(const std::string& dir);
  /// Removes the generation folder unless commit() succeeded.
  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  /// keyframes.bin and graph.bin. Throws SessionError.
  void writeBackend(const BackendSnapshot& snapshot);
  /// vocabulary.voc. Throws SessionError.
  void writeVocabulary(const Vocabulary& vocabulary);
  /// A text file of the generation (config.yaml). Throws SessionError.
  void writeText(const std::string& name, const std::string& text);
  /// Where a file of the generation written by someone else goes (map.ot by the Mapper)...
  /// Throws SessionError for a name that is not a plain file name (a '/', "..", a space).
  std::string pathFor(const std::string& name) const;
  /// ...and the call that adds it to the manifest once written. Throws SessionError when it
  /// does not exist.
  void addFile(const std::string& name);

  /// Writes manifest.txt (with `info`'s provenance and summary; files, sizes and checksums
  /// filled in here), fsyncs the generation folder, points CURRENT at it, then removes older
  /// generations. Throws SessionError; on failure the previous session stays current.
  void commit(SessionInfo info);

  const std::string& generationPath() const { return generation_path_; }

 private:
  /// A file of the generation as the manifest lists it.
  struct FileEntry {
    std::string name;
    std::uint64_t size = 0;      ///< bytes
    std::uint64_t checksum = 0;  ///< fnv1a64 of the content
  };
  /// Writes `name` crash-safely from `content` (called with a stream; returns false to abandon)
  /// and lists it with its size and checksum.
  void writeFile(const std::string& name, const std::function<bool(std::ostream&)>& content);
  void listFile(FileEntry entry);

  std::string dir_;
  std::string generation_;       ///< folder name, e.g. generation-000007
  std::string generation_path_;  ///< dir_/generation_
  std::vector<FileEntry> files_;
  bool committed_ = false;
};

/// Reads the session CURRENT names in `dir`, verifying everything (see the file comment).
/// Throws SessionError naming the file and the problem.
Session loadSession(const std::string& dir);

/// Only the manifest of the current generation (checked, but the other files are not read or
/// verified). Throws SessionError.
SessionInfo readSessionInfo(const std::string& dir);

/// Parses the contents of keyframes.bin and graph.bin into a snapshot and checks its consistency
/// (see the file comment), without the manifest's size and checksum verification: what
/// loadSession() does once the files are verified, exposed so tests can feed it arbitrary bytes.
/// `label` is the generation folder named in errors ("session <label>/graph.bin: truncated (edge
/// 17 of 40)"). Throws SessionError; never crashes or allocates beyond the input's size.
BackendSnapshot parseBackendFiles(const std::vector<std::uint8_t>& keyframes_bin,
                                  const std::vector<std::uint8_t>& graph_bin,
                                  const std::string& label);

/// The summary counts of a snapshot (keyframes, culled keyframes, landmarks, edges, segments,
/// loops, keyframe extent) filled into `info`.
void summarizeSnapshot(const BackendSnapshot& snapshot, SessionInfo& info);

/// An empty string when `loaded` (a session's camera) is the camera `current` within 0.5 pixel
/// in focal lengths and principal point, the same image size and distortion (model, and the
/// coefficients when there is a model); otherwise what differs, e.g. "image size 640x480 in the
/// session, 320x240 now; fx 525 px in the session, 262.5 px now".
std::string cameraMismatch(const CameraIntrinsics& loaded, const CameraIntrinsics& current);

}  // namespace slamd
