#include "slamd/mapping/keyframe_cloud_io.hpp"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>

#include "slamd/common/binary_codec.hpp"
#include "slamd/common/file_io.hpp"

namespace slamd {

namespace {

constexpr char kMagic[8] = {'S', 'L', 'A', 'M', 'D', 'K', 'F', 'C'};
/// Bytes of a record besides its points and colours: id, utime, pose, part_points,
/// parts_in_map, point count, colour flag.
constexpr std::uint64_t kRecordFixedBytes = 8 + 8 + 12 * 8 + 8 + 4 + 8 + 1;
constexpr std::uint64_t kPointBytes = 3 * sizeof(float);
constexpr std::uint64_t kColorBytes = 3;
constexpr std::uint64_t kChecksumBytes = 8;
static_assert(sizeof(ColorBgr) == kColorBytes, "colours are read straight into ColorBgr");
static_assert(sizeof(Eigen::Vector3f) == kPointBytes, "points are read straight into Vector3f");
static_assert(sizeof(std::size_t) == sizeof(std::uint64_t), "part_points is stored as 64 bits");

bool fail(std::string* error, const std::string& text) {
  if (error != nullptr) *error = text;
  return false;
}

/// Why a file is refused (caught in readKeyframeCloudRecords, which prefixes the path).
class FormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

std::string ofCount(std::uint64_t index, std::uint64_t count) {
  return "record " + std::to_string(index + 1) + " of " + std::to_string(count);
}

/// Checks that `count` items of `item_bytes` each (plus `after` bytes that must follow them) fit
/// in what is left of the file, before anything is allocated for them.
void checkFits(const LittleEndianReader& in, std::uint64_t count, std::uint64_t item_bytes,
               std::uint64_t after, const std::string& what) {
  if (!in.fits(count, item_bytes, after)) {
    throw FormatError("truncated or corrupt (" + what + " " + std::to_string(count) +
                      " cannot fit in the " + std::to_string(in.remaining()) + " bytes left)");
  }
}

void readRecord(LittleEndianReader& in, const std::string& where, KeyframeCloudRecord& record) {
  in.setWhere(where);
  record.id = in.i64();
  record.utime = in.i64();
  record.T_world_camera_in_map = readPose(in);
  record.part_points = static_cast<std::size_t>(in.u64());
  record.parts_in_map = in.i32();

  const std::uint64_t count = in.u64();
  checkFits(in, count, kPointBytes, 1 + kChecksumBytes, where + ": point count");
  std::vector<Eigen::Vector3f>& points = record.cloud_camera.points;
  // Straight into the points, decoded in place: the bytes are never held twice.
  points.resize(static_cast<std::size_t>(count));
  in.setWhere(where + ", points");
  if (count > 0) in.f32s(points.front().data(), static_cast<std::size_t>(count) * 3);
  in.setWhere(where + ", colours");
  const std::uint8_t color_flag = in.u8();
  std::vector<ColorBgr>& colors = record.cloud_camera.colors_bgr;
  colors.clear();
  if (color_flag > 1) {
    throw FormatError(where + ": colour flag " + std::to_string(color_flag) +
                      " is neither 0 nor 1 (corrupt)");
  }
  if (color_flag == 1) {
    checkFits(in, count, kColorBytes, kChecksumBytes, where + ": colour count");
    colors.resize(static_cast<std::size_t>(count));
    if (count > 0) in.raw(colors.data(), count * kColorBytes);
  }
}

/// Parses the whole file; throws FormatError.
void readRecords(std::istream& stream, std::uint64_t size,
                 std::vector<KeyframeCloudRecord>& records) {
  LittleEndianReader in(stream, size);
  in.startChecksum();
  in.setWhere("header");
  char magic[sizeof(kMagic)] = {};
  if (size < sizeof(magic)) throw FormatError("too short to be a slamd keyframe cloud file");
  in.raw(magic, sizeof(magic));
  if (std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
    throw FormatError("not a slamd keyframe cloud file (bad magic)");
  }
  const std::uint32_t version = in.u32();
  if (version != kKeyframeCloudFileVersion) {
    const std::string versions = "format version " + std::to_string(version) +
                                 ", this slamd reads " + std::to_string(kKeyframeCloudFileVersion);
    throw FormatError(version > kKeyframeCloudFileVersion
                          ? "written by a newer slamd (" + versions + ")"
                          : "an older format (" + versions + ")");
  }
  in.setWhere("record count");
  const std::uint64_t count = in.u64();
  checkFits(in, count, kRecordFixedBytes, kChecksumBytes, "record count");
  // The rest grows with records really read (each takes at least kRecordFixedBytes of the file).
  records.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(count, 1024)));
  for (std::uint64_t i = 0; i < count; ++i) {
    readRecord(in, ofCount(i, count), records.emplace_back());
  }
  const std::uint64_t computed = in.checksum();
  in.setWhere("checksum");
  if (in.u64() != computed) throw FormatError("checksum mismatch (corrupt)");
  if (in.remaining() != 0) {
    throw FormatError(std::to_string(in.remaining()) + " unexpected bytes after the checksum");
  }
}

}  // namespace

bool writeKeyframeCloudRecords(const std::string& path,
                               const std::vector<KeyframeCloudRecord>& records,
                               std::string* error) {
  for (const KeyframeCloudRecord& record : records) {
    const PointCloud& cloud = record.cloud_camera;
    if (cloud.hasColor() && cloud.colors_bgr.size() != cloud.points.size()) {
      return fail(error, "cannot write " + path + ": keyframe " + std::to_string(record.id) +
                             " has " + std::to_string(cloud.colors_bgr.size()) + " colours for " +
                             std::to_string(cloud.points.size()) + " points");
    }
  }
  return writeFileAtomically(
      path,
      [&records](std::ostream& out) {
        // Written a record at a time, the checksum following the bytes: the clouds are never
        // held twice.
        LittleEndianWriter w(out);
        w.startChecksum();
        w.raw(kMagic, sizeof(kMagic));
        w.u32(kKeyframeCloudFileVersion);
        w.u64(records.size());
        for (const KeyframeCloudRecord& record : records) {
          w.i64(record.id);
          w.i64(record.utime);
          writePose(w, record.T_world_camera_in_map);
          w.u64(record.part_points);
          w.i32(record.parts_in_map);
          const PointCloud& cloud = record.cloud_camera;
          w.u64(cloud.points.size());
          for (const Eigen::Vector3f& p : cloud.points) {
            w.f32(p.x());
            w.f32(p.y());
            w.f32(p.z());
          }
          w.u8(cloud.hasColor() ? 1 : 0);
          if (!cloud.colors_bgr.empty()) {
            w.raw(cloud.colors_bgr.data(), cloud.colors_bgr.size() * kColorBytes);
          }
          if (!w.flush()) return false;
        }
        w.u64(w.checksum());
        return w.flush();
      },
      error);
}

bool readKeyframeCloudRecords(const std::string& path, std::vector<KeyframeCloudRecord>& records,
                              std::string* error) {
  records.clear();
  // Only regular files: a FIFO would block forever and a directory has no meaningful size.
  std::error_code status_error;
  const auto status = std::filesystem::status(path, status_error);
  if (status_error) return fail(error, "cannot open " + path + ": " + status_error.message());
  if (status.type() != std::filesystem::file_type::regular) {
    return fail(error, path + " is not a regular file");
  }
  std::error_code size_error;
  const std::uintmax_t size = std::filesystem::file_size(path, size_error);
  if (size_error) return fail(error, "cannot read " + path + ": " + size_error.message());
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(error, "cannot open " + path);
  try {
    readRecords(in, static_cast<std::uint64_t>(size), records);
  } catch (const FormatError& e) {
    records.clear();
    return fail(error, path + ": " + e.what());
  } catch (const TruncatedBinaryError& e) {
    records.clear();
    return fail(
        error, path + ": truncated (" + e.where() + ", " + std::to_string(size) + " bytes in all)");
  } catch (const std::bad_alloc&) {
    records.clear();
    return fail(error, path + ": out of memory for its " + std::to_string(size) + " bytes");
  }
  return true;
}

}  // namespace slamd
