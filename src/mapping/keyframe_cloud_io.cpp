#include "slamd/mapping/keyframe_cloud_io.hpp"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>

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
static_assert(sizeof(std::size_t) == sizeof(std::uint64_t), "part_points is stored as 64 bits");

bool fail(std::string* error, const std::string& text) {
  if (error != nullptr) *error = text;
  return false;
}

/// Appends little-endian values to a byte string.
class ByteWriter {
 public:
  explicit ByteWriter(std::string& out) : out_(out) {}
  void u8(std::uint8_t v) { out_.push_back(static_cast<char>(v)); }
  void u32(std::uint32_t v) { little(v, 4); }
  void u64(std::uint64_t v) { little(v, 8); }
  void i32(std::int32_t v) { little(static_cast<std::uint32_t>(v), 4); }
  void i64(std::int64_t v) { little(static_cast<std::uint64_t>(v), 8); }
  void f32(float v) {
    std::uint32_t bits = 0;
    std::memcpy(&bits, &v, sizeof(bits));
    u32(bits);
  }
  void f64(double v) {
    std::uint64_t bits = 0;
    std::memcpy(&bits, &v, sizeof(bits));
    u64(bits);
  }

 private:
  void little(std::uint64_t v, int size) {
    for (int i = 0; i < size; ++i) out_.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  }
  std::string& out_;
};

/// Why a file is refused (caught in readKeyframeCloudRecords, which prefixes the path).
class FormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Reads little-endian values from a stream of known size, hashing every byte it reads; throws
/// FormatError when the bytes run out.
class ByteReader {
 public:
  ByteReader(std::istream& in, std::uint64_t size) : in_(in), size_(size) {}

  std::uint64_t remaining() const { return size_ - position_; }
  std::uint64_t checksum() const { return checksum_; }
  /// Names what is being read, for the truncation message.
  void setWhere(std::string where) { where_ = std::move(where); }
  [[noreturn]] void truncated() const {
    throw FormatError("truncated (" + where_ + ", " + std::to_string(size_) + " bytes in all)");
  }

  void raw(void* out, std::uint64_t size) {
    if (size > remaining()) truncated();
    // A file that shrank since its size was taken reads short: truncated as well.
    if (!in_.read(static_cast<char*>(out), static_cast<std::streamsize>(size))) truncated();
    checksum_ = fnv1a64(out, static_cast<std::size_t>(size), checksum_);
    position_ += size;
  }
  std::uint8_t u8() { return static_cast<std::uint8_t>(little(1)); }
  std::uint32_t u32() { return static_cast<std::uint32_t>(little(4)); }
  std::uint64_t u64() { return little(8); }
  std::int32_t i32() { return static_cast<std::int32_t>(u32()); }
  std::int64_t i64() { return static_cast<std::int64_t>(u64()); }
  double f64() {
    const std::uint64_t bits = u64();
    double v = 0.0;
    std::memcpy(&v, &bits, sizeof(v));
    return v;
  }

 private:
  std::uint64_t little(int size) {
    std::uint8_t bytes[8] = {};
    raw(bytes, static_cast<std::uint64_t>(size));
    std::uint64_t v = 0;
    for (int i = 0; i < size; ++i) v |= static_cast<std::uint64_t>(bytes[i]) << (8 * i);
    return v;
  }

  std::istream& in_;
  std::uint64_t size_;
  std::uint64_t position_ = 0;
  std::uint64_t checksum_ = kFnv1a64Basis;
  std::string where_ = "header";
};

std::string ofCount(std::uint64_t index, std::uint64_t count) {
  return "record " + std::to_string(index + 1) + " of " + std::to_string(count);
}

/// Checks that `count` items of `item_bytes` each (plus `after` bytes that must follow them) fit
/// in what is left of the file, before anything is allocated for them.
void checkFits(const ByteReader& in, std::uint64_t count, std::uint64_t item_bytes,
               std::uint64_t after, const std::string& what) {
  const std::uint64_t left = in.remaining() > after ? in.remaining() - after : 0;
  if (count > left / item_bytes) {
    throw FormatError("truncated or corrupt (" + what + " " + std::to_string(count) +
                      " cannot fit in the " + std::to_string(in.remaining()) + " bytes left)");
  }
}

void readRecord(ByteReader& in, const std::string& where, KeyframeCloudRecord& record) {
  in.setWhere(where);
  record.id = in.i64();
  record.utime = in.i64();
  SE3 T = SE3::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = in.f64();
  }
  for (int r = 0; r < 3; ++r) T.translation()(r) = in.f64();
  record.T_world_camera_in_map = T;
  record.part_points = static_cast<std::size_t>(in.u64());
  record.parts_in_map = in.i32();

  const std::uint64_t count = in.u64();
  checkFits(in, count, kPointBytes, 1 + kChecksumBytes, where + ": point count");
  std::vector<Eigen::Vector3f>& points = record.cloud_camera.points;
  points.clear();
  points.reserve(static_cast<std::size_t>(count));
  // In pieces: the bytes are decoded as they come, never held twice.
  constexpr std::uint64_t kPiecePoints = 1024;
  std::uint8_t piece[kPiecePoints * kPointBytes];
  in.setWhere(where + ", points");
  for (std::uint64_t done = 0; done < count;) {
    const std::uint64_t n = std::min(kPiecePoints, count - done);
    in.raw(piece, n * kPointBytes);
    for (std::uint64_t i = 0; i < n; ++i) {
      float xyz[3];
      for (int k = 0; k < 3; ++k) {
        const std::uint8_t* b = piece + i * kPointBytes + 4 * static_cast<std::uint64_t>(k);
        const std::uint32_t bits =
            static_cast<std::uint32_t>(b[0]) | static_cast<std::uint32_t>(b[1]) << 8 |
            static_cast<std::uint32_t>(b[2]) << 16 | static_cast<std::uint32_t>(b[3]) << 24;
        std::memcpy(&xyz[k], &bits, sizeof(float));
      }
      points.emplace_back(xyz[0], xyz[1], xyz[2]);
    }
    done += n;
  }
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
  ByteReader in(stream, size);
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
        std::uint64_t checksum = kFnv1a64Basis;
        std::string buffer;
        ByteWriter w(buffer);
        const auto flush = [&]() {
          checksum = fnv1a64(buffer.data(), buffer.size(), checksum);
          out.write(buffer.data(), static_cast<std::streamsize>(buffer.size()));
          buffer.clear();
          return out.good();
        };
        buffer.append(kMagic, sizeof(kMagic));
        w.u32(kKeyframeCloudFileVersion);
        w.u64(records.size());
        for (const KeyframeCloudRecord& record : records) {
          w.i64(record.id);
          w.i64(record.utime);
          const SE3& T = record.T_world_camera_in_map;
          for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) w.f64(T.linear()(r, c));
          }
          for (int r = 0; r < 3; ++r) w.f64(T.translation()(r));
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
          for (const ColorBgr& c : cloud.colors_bgr) {
            for (const std::uint8_t channel : c) w.u8(channel);
          }
          if (!flush()) return false;
        }
        if (!flush()) return false;
        w.u64(checksum);
        out.write(buffer.data(), static_cast<std::streamsize>(buffer.size()));
        return out.good();
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
  } catch (const std::bad_alloc&) {
    records.clear();
    return fail(error, path + ": out of memory for its " + std::to_string(size) + " bytes");
  }
  return true;
}

}  // namespace slamd
