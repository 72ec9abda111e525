#pragma once
// The mapper's kept keyframe clouds as records, and their file format, so that a session can
// save them next to its map (map.ot) and a later run can restore them: the loaded map then
// follows corrections like the map that was saved.
//
//   Mapper::keyframeCloudRecords() -> writeKeyframeCloudRecords(path, records)   (saving)
//   readKeyframeCloudRecords(path, records) -> Mapper::loadMap(map.ot) ->
//       Mapper::restoreKeyframeClouds(std::move(records))                        (loading)
//
// Format (kKeyframeCloudFileVersion), little-endian: the magic "SLAMDKFC", the version (uint32),
// the record count (uint64), then per record: id (int64), utime (int64), T_world_camera_in_map
// as 12 doubles (the rotation row-major, then the translation), part_points (uint64),
// parts_in_map (int32), the point count (uint64), the points (3 floats each: x, y, z), a colour
// flag (uint8: 0 none, 1 one colour per point) and, when 1, the colours (3 bytes each: b, g, r);
// last, the FNV-1a checksum (uint64, fnv1a64) of every byte before it. Every count is checked
// against the bytes that remain before anything is allocated. The reader checks the format only;
// Mapper::restoreKeyframeClouds() checks each record's content (finite, consistent).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "slamd/common/se3.hpp"
#include "slamd/common/time.hpp"
#include "slamd/mapping/point_cloud.hpp"

namespace slamd {

/// The format version writeKeyframeCloudRecords() writes and readKeyframeCloudRecords() reads.
inline constexpr std::uint32_t kKeyframeCloudFileVersion = 1;

/// A kept keyframe cloud as it stands in the map (sessions save and restore them).
struct KeyframeCloudRecord {
  std::int64_t id = 0;  ///< keyframe id
  Utime utime = 0;      ///< capture time of the keyframe, microseconds since the Unix epoch
  /// Camera optical frame (x right, y down, z forward), metres, in the mapper's part order (part
  /// k is points k * part_points .. (k + 1) * part_points - 1). Colours empty or one per point.
  PointCloud cloud_camera;
  /// Pose of the camera in the map frame at which its parts in the map went in (with
  /// parts_in_map 0: the pose it goes in at next).
  SE3 T_world_camera_in_map = SE3::Identity();
  std::size_t part_points = 1;  ///< points per part (the last part may hold fewer)
  int parts_in_map = 0;         ///< parts 0 .. parts_in_map - 1 are in the map
};

/// Writes `records` to `path` crash-safely (writeFileAtomically) in the format above. False with
/// a sentence in *error on failure (the file at `path`, if any, is then unchanged).
bool writeKeyframeCloudRecords(const std::string& path,
                               const std::vector<KeyframeCloudRecord>& records,
                               std::string* error = nullptr);

/// Reads what writeKeyframeCloudRecords() wrote into `records` (replaced). False with a sentence
/// in *error naming the file and the problem (not this format, another version, truncated,
/// checksum mismatch, absurd counts, bytes after the end), and `records` empty. Never crashes, and
/// allocates no more than the file's size warrants, whatever the bytes.
bool readKeyframeCloudRecords(const std::string& path, std::vector<KeyframeCloudRecord>& records,
                              std::string* error = nullptr);

}  // namespace slamd
