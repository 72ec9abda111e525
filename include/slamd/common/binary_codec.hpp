#pragma once
// Little-endian binary encoding, shared by slamd's binary file formats (session keyframes.bin and
// graph.bin, keyframe_clouds.bin, the vocabulary): the byte order is fixed, whatever the host's.
//
//   std::string bytes;
//   LittleEndianWriter out(bytes);           // or (std::ostream&), or (std::vector<uint8_t>&)
//   out.raw(kMagic, sizeof(kMagic));
//   out.u32(kVersion);
//   out.u64(items.size());
//
//   LittleEndianReader in(bytes);            // or (std::istream&, size) to stream a large file
//   try {
//     in.setWhere("header");
//     const std::uint32_t version = in.u32();
//     in.setWhere("count of items");
//     const std::uint64_t count = in.u64();
//     if (!in.fits(count, kItemBytes)) in.truncated();   // before allocating for them
//   } catch (const TruncatedBinaryError& e) {
//     report(path + ": " + e.what());        // "truncated (count of items)"
//   }
//
// A read past the end throws TruncatedBinaryError naming what was being read (setWhere), so that
// each format words its own message around it. Both sides can keep a running FNV-1a checksum
// (fnv1a64) of the bytes that pass through them from startChecksum() on. Neither is thread-safe:
// one thread owns each.

#include <cstddef>
#include <cstdint>
#include <istream>
#include <limits>
#include <ostream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "slamd/common/file_io.hpp"
#include "slamd/common/se3.hpp"

namespace slamd {

/// Thrown by LittleEndianReader when a read asks for more bytes than remain (or the stream ends
/// early). what() is "truncated" or "truncated (<where>)".
class TruncatedBinaryError : public std::runtime_error {
 public:
  explicit TruncatedBinaryError(std::string where);
  /// What was being read (LittleEndianReader::where() at the time); may be empty.
  const std::string& where() const { return where_; }

 private:
  std::string where_;
};

/// Encodes values little-endian onto a byte string, a byte vector or an output stream.
///
/// The string and vector sinks are appended to directly (they must outlive the writer). The
/// stream sink is buffered: the buffer goes out when it reaches kStreamBufferBytes, on flush()
/// and, as a last resort, in the destructor (a raw() block that large goes out at once); call
/// flush() to learn whether every write succeeded.
class LittleEndianWriter {
 public:
  /// Bytes buffered for a stream sink before they are written out.
  static constexpr std::size_t kStreamBufferBytes = 1 << 16;

  explicit LittleEndianWriter(std::string& out);
  explicit LittleEndianWriter(std::vector<std::uint8_t>& out);
  explicit LittleEndianWriter(std::ostream& out);
  ~LittleEndianWriter();
  LittleEndianWriter(const LittleEndianWriter&) = delete;
  LittleEndianWriter& operator=(const LittleEndianWriter&) = delete;

  void u8(std::uint8_t v) { raw(&v, 1); }
  void u16(std::uint16_t v) { little(v, 2); }
  void u32(std::uint32_t v) { little(v, 4); }
  void u64(std::uint64_t v) { little(v, 8); }
  void i32(std::int32_t v) { u32(static_cast<std::uint32_t>(v)); }
  void i64(std::int64_t v) { u64(static_cast<std::uint64_t>(v)); }
  /// IEEE 754 bits, so NaN payloads, -0.0 and denormals survive.
  void f32(float v);
  void f64(double v);
  /// `size` bytes as they are (magic strings, byte arrays).
  void raw(const void* data, std::size_t size);

  /// Starts a running FNV-1a of every byte written from now on, continuing from `seed`.
  void startChecksum(std::uint64_t seed = kFnv1a64Basis);
  /// The running checksum (kFnv1a64Basis, or the seed, when nothing was written since
  /// startChecksum()).
  std::uint64_t checksum() const { return checksum_; }
  /// Bytes written through this writer since construction.
  std::uint64_t bytesWritten() const { return written_; }

  /// Stream sink: writes out the buffer; false when any write to the stream has failed so far.
  /// Other sinks: true.
  bool flush();

 private:
  void little(std::uint64_t v, int size);

  std::string* string_ = nullptr;
  std::vector<std::uint8_t>* vector_ = nullptr;
  std::ostream* stream_ = nullptr;
  std::string buffer_;  ///< the stream sink's pending bytes (string_ points here)
  bool stream_ok_ = true;
  bool checksumming_ = false;
  std::uint64_t checksum_ = kFnv1a64Basis;
  std::uint64_t written_ = 0;
};

/// Decodes little-endian values from a memory buffer or from an input stream.
///
/// A memory source is read in place (it must outlive the reader). A stream source is read as
/// the values are asked for, never more: a file larger than memory streams through, and the
/// stream is left just after the last value read. Given its size, remaining() and fits() check
/// counts against it; a stream of unknown size (kUnknownSize) ends where a read comes back short.
/// Every read past the end throws TruncatedBinaryError and leaves position() unchanged; a read
/// past a known size is refused before it touches the source.
class LittleEndianReader {
 public:
  /// The size of a stream whose length is not known in advance.
  static constexpr std::uint64_t kUnknownSize = std::numeric_limits<std::uint64_t>::max();

  LittleEndianReader(const void* data, std::size_t size);
  explicit LittleEndianReader(const std::vector<std::uint8_t>& bytes);
  explicit LittleEndianReader(const std::string& bytes);
  /// `size`: the bytes the stream holds from its current position (e.g. the file's size).
  explicit LittleEndianReader(std::istream& in, std::uint64_t size = kUnknownSize);
  LittleEndianReader(const LittleEndianReader&) = delete;
  LittleEndianReader& operator=(const LittleEndianReader&) = delete;

  /// Names what is being read, for the truncation message (e.g. "edge 17 of 40").
  void setWhere(std::string where) { where_ = std::move(where); }
  const std::string& where() const { return where_; }
  /// Throws TruncatedBinaryError naming where().
  [[noreturn]] void truncated() const;

  /// The source's size in bytes (kUnknownSize for a stream of unknown size).
  std::uint64_t size() const { return size_; }
  /// Bytes read so far.
  std::uint64_t position() const { return position_; }
  /// Bytes left before the end (meaningless for a stream of unknown size).
  std::uint64_t remaining() const { return size_ - position_; }
  /// True when `count` items of `item_bytes` each, followed by `reserved_bytes` more, fit in the
  /// bytes that remain: a count read from a file is checked before anything is allocated for it.
  bool fits(std::uint64_t count, std::uint64_t item_bytes, std::uint64_t reserved_bytes = 0) const;

  std::uint8_t u8() { return static_cast<std::uint8_t>(little(1)); }
  std::uint16_t u16() { return static_cast<std::uint16_t>(little(2)); }
  std::uint32_t u32() { return static_cast<std::uint32_t>(little(4)); }
  std::uint64_t u64() { return little(8); }
  std::int32_t i32() { return static_cast<std::int32_t>(u32()); }
  std::int64_t i64() { return static_cast<std::int64_t>(u64()); }
  float f32();
  double f64();
  /// `count` floats into `out` in one read (bulk data such as point clouds).
  void f32s(float* out, std::size_t count);
  /// `size` bytes as they are into `out`.
  void raw(void* out, std::uint64_t size);

  /// Starts a running FNV-1a of every byte read from now on, continuing from `seed`.
  void startChecksum(std::uint64_t seed = kFnv1a64Basis);
  /// The running checksum of the bytes read since startChecksum().
  std::uint64_t checksum() const { return checksum_; }

 private:
  std::uint64_t little(int size);

  const std::uint8_t* data_ = nullptr;  ///< memory source
  std::istream* stream_ = nullptr;      ///< stream source
  std::uint64_t size_;
  std::uint64_t position_ = 0;
  bool checksumming_ = false;
  std::uint64_t checksum_ = kFnv1a64Basis;
  std::string where_;
};

/// The pose layout of slamd's binary files: 12 doubles, the rotation row-major, then the
/// translation (96 bytes).
inline constexpr std::size_t kBinaryPoseBytes = 12 * 8;
void writePose(LittleEndianWriter& out, const SE3& T);
/// Reads what writePose() wrote; the rotation is not checked (the formats check it).
SE3 readPose(LittleEndianReader& in);

}  // namespace slamd
