#include "slamd/common/binary_codec.hpp"

#include <cstring>

namespace slamd {

namespace {

/// The value of `size` little-endian bytes.
std::uint64_t decodeLittle(const std::uint8_t* bytes, int size) {
  std::uint64_t v = 0;
  for (int i = 0; i < size; ++i) v |= static_cast<std::uint64_t>(bytes[i]) << (8 * i);
  return v;
}

}  // namespace

TruncatedBinaryError::TruncatedBinaryError(std::string where)
    : std::runtime_error(where.empty() ? "truncated" : "truncated (" + where + ")"),
      where_(std::move(where)) {}

// ---------------------------------------------------------------------------------------------
// LittleEndianWriter.

LittleEndianWriter::LittleEndianWriter(std::string& out) : string_(&out) {}

LittleEndianWriter::LittleEndianWriter(std::vector<std::uint8_t>& out) : vector_(&out) {}

LittleEndianWriter::LittleEndianWriter(std::ostream& out) : string_(&buffer_), stream_(&out) {}

LittleEndianWriter::~LittleEndianWriter() {
  // A last resort for a caller that did not flush(): its failure cannot be reported from here,
  // and a stream set to throw must not end the program from a destructor.
  try {
    flush();
  } catch (...) {
  }
}

void LittleEndianWriter::f32(float v) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &v, sizeof(bits));
  u32(bits);
}

void LittleEndianWriter::f64(double v) {
  std::uint64_t bits = 0;
  std::memcpy(&bits, &v, sizeof(bits));
  u64(bits);
}

void LittleEndianWriter::raw(const void* data, std::size_t size) {
  if (size == 0) return;
  if (checksumming_) checksum_ = fnv1a64(data, size, checksum_);
  written_ += size;
  if (vector_ != nullptr) {
    const auto* bytes = static_cast<const std::uint8_t*>(data);
    vector_->insert(vector_->end(), bytes, bytes + size);
    return;
  }
  if (stream_ != nullptr && size >= kStreamBufferBytes) {
    // Large blocks go straight to the stream rather than through a second copy in the buffer.
    flush();
    stream_->write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
    return;
  }
  string_->append(static_cast<const char*>(data), size);
  if (stream_ != nullptr && buffer_.size() >= kStreamBufferBytes) flush();
}

void LittleEndianWriter::startChecksum(std::uint64_t seed) {
  checksumming_ = true;
  checksum_ = seed;
}

bool LittleEndianWriter::flush() {
  if (stream_ == nullptr) return true;
  if (!buffer_.empty()) {
    stream_->write(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
    buffer_.clear();
  }
  // Sticky: a write that failed while buffering is still reported by the final flush().
  stream_ok_ = stream_ok_ && stream_->good();
  return stream_ok_;
}

void LittleEndianWriter::little(std::uint64_t v, int size) {
  std::uint8_t bytes[8];
  for (int i = 0; i < size; ++i) bytes[i] = static_cast<std::uint8_t>((v >> (8 * i)) & 0xffu);
  raw(bytes, static_cast<std::size_t>(size));
}

// ---------------------------------------------------------------------------------------------
// LittleEndianReader.

LittleEndianReader::LittleEndianReader(const void* data, std::size_t size)
    : data_(static_cast<const std::uint8_t*>(data)), size_(size) {}

LittleEndianReader::LittleEndianReader(const std::vector<std::uint8_t>& bytes)
    : LittleEndianReader(bytes.data(), bytes.size()) {}

LittleEndianReader::LittleEndianReader(const std::string& bytes)
    : LittleEndianReader(bytes.data(), bytes.size()) {}

LittleEndianReader::LittleEndianReader(std::istream& in, std::uint64_t size)
    : stream_(&in), size_(size) {}

void LittleEndianReader::truncated() const { throw TruncatedBinaryError(where_); }

bool LittleEndianReader::fits(std::uint64_t count, std::uint64_t item_bytes,
                              std::uint64_t reserved_bytes) const {
  const std::uint64_t left = remaining() > reserved_bytes ? remaining() - reserved_bytes : 0;
  return item_bytes == 0 || count <= left / item_bytes;
}

float LittleEndianReader::f32() {
  const std::uint32_t bits = u32();
  float v = 0.0f;
  std::memcpy(&v, &bits, sizeof(v));
  return v;
}

double LittleEndianReader::f64() {
  const std::uint64_t bits = u64();
  double v = 0.0;
  std::memcpy(&v, &bits, sizeof(v));
  return v;
}

void LittleEndianReader::f32s(float* out, std::size_t count) {
  if (count > remaining() / sizeof(float)) truncated();
  raw(out, static_cast<std::uint64_t>(count) * sizeof(float));
  // Decoded in place: a no-op pass on a little-endian host, a byte swap on any other.
  auto* bytes = reinterpret_cast<std::uint8_t*>(out);
  for (std::size_t i = 0; i < count; ++i) {
    const auto bits = static_cast<std::uint32_t>(decodeLittle(bytes + 4 * i, 4));
    std::memcpy(out + i, &bits, sizeof(float));
  }
}

void LittleEndianReader::raw(void* out, std::uint64_t size) {
  if (size > remaining()) truncated();
  if (size == 0) return;
  if (stream_ != nullptr) {
    // A stream that ends early (a file that shrank since its size was taken) is truncated too.
    if (!stream_->read(static_cast<char*>(out), static_cast<std::streamsize>(size))) truncated();
  } else {
    std::memcpy(out, data_ + position_, static_cast<std::size_t>(size));
  }
  if (checksumming_) checksum_ = fnv1a64(out, static_cast<std::size_t>(size), checksum_);
  position_ += size;
}

void LittleEndianReader::startChecksum(std::uint64_t seed) {
  checksumming_ = true;
  checksum_ = seed;
}

std::uint64_t LittleEndianReader::little(int size) {
  std::uint8_t bytes[8] = {};
  raw(bytes, static_cast<std::uint64_t>(size));
  return decodeLittle(bytes, size);
}

// ---------------------------------------------------------------------------------------------
// Poses.

void writePose(LittleEndianWriter& out, const SE3& T) {
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out.f64(T.linear()(r, c));
  }
  for (int r = 0; r < 3; ++r) out.f64(T.translation()(r));
}

SE3 readPose(LittleEndianReader& in) {
  SE3 T = SE3::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = in.f64();
  }
  for (int r = 0; r < 3; ++r) T.translation()(r) = in.f64();
  return T;
}

}  // namespace slamd
