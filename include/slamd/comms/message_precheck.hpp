#pragma once
// Structural pre-check of encoded LCM messages, run before lcm-gen's decoder.
//
// Why: LCM 1.3.1's generated decoders resize a vector to the count read from the wire *before*
// checking that the buffer holds that many elements. A corrupt count in one malformed message
// makes the decoder allocate (and zero) gigabytes, enough to get a robot's daemon OOM-killed.
// For every type slamd receives that has a variable-length array, this walks the encoding (big-
// endian, as LCM writes it) and rejects counts that cannot fit in the remaining bytes.
// Types without variable-length arrays need no pre-check (the primary template accepts).

#include <cstdint>
#include <cstring>
#include <string>

#include "bot_core/pose_t.hpp"
#include "kinect/frame_msg_t.hpp"
#include "slamd/keyframe_trajectory_t.hpp"
#include "slamd/rgbd_frame_t.hpp"
#include "slamd/status_t.hpp"
#include "slamd/voxel_map_t.hpp"
#include "slamd/voxel_map_update_t.hpp"

namespace slamd {

/// Reads an LCM encoding field by field without allocating; any read past the end fails.
class LcmFieldWalker {
 public:
  LcmFieldWalker(const void* data, std::size_t size)
      : data_(static_cast<const std::uint8_t*>(data)), size_(size) {}

  bool skip(std::size_t bytes) {
    if (bytes > size_ - pos_) return fail();
    pos_ += bytes;
    return true;
  }
  bool readInt32(std::int32_t& value) {
    if (4 > size_ - pos_) return fail();
    const std::uint8_t* p = data_ + pos_;
    value = static_cast<std::int32_t>((std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) |
                                      (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]});
    pos_ += 4;
    return true;
  }
  bool readInt16(std::int16_t& value) {
    if (2 > size_ - pos_) return fail();
    value = static_cast<std::int16_t>((data_[pos_] << 8) | data_[pos_ + 1]);
    pos_ += 2;
    return true;
  }
  /// An LCM string: int32 length (including the terminating NUL) then the bytes.
  bool skipString() {
    std::int32_t length = 0;
    return readInt32(length) && length >= 0 && skip(static_cast<std::size_t>(length));
  }
  /// A count of elements each taking at least `min_element_bytes` in the encoding.
  bool readCount(std::int32_t& count, std::size_t min_element_bytes) {
    if (!readInt32(count)) return false;
    if (count < 0) return fail();
    if (static_cast<std::size_t>(count) * min_element_bytes > size_ - pos_) return fail();
    return true;
  }
  bool ok() const { return ok_; }

 private:
  bool fail() {
    ok_ = false;
    return false;
  }
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  bool ok_ = true;
};

template <typename Message>
struct MessagePrecheck {
  static bool plausible(const void*, std::size_t) { return true; }
};

template <>
struct MessagePrecheck<slamd::rgbd_frame_t> {
  static bool plausible(const void* data, std::size_t size) {
    LcmFieldWalker w(data, size);
    std::int32_t count = 0;
    // hash, utime, sequence, frame_id, fx fy cx cy, width height, distortion_model,
    // distortion[5], depth_scale, color_encoding, color_nbytes, color_data, depth_encoding, ...
    return w.skip(8 + 8 + 8) && w.skipString() && w.skip(4 * 8 + 2 * 4 + 1 + 5 * 8 + 8 + 1) &&
           w.readCount(count, 1) && w.skip(static_cast<std::size_t>(count)) && w.skip(1) &&
           w.readCount(count, 1);
  }
};

template <>
struct MessagePrecheck<slamd::voxel_map_t> {
  static bool plausible(const void* data, std::size_t size) {
    LcmFieldWalker w(data, size);
    std::int32_t count = 0;
    // hash, utime, resolution, frame_id, update_sequence, num_bytes
    return w.skip(8 + 8 + 8) && w.skipString() && w.skip(8) && w.readCount(count, 1);
  }
};

template <>
struct MessagePrecheck<slamd::voxel_map_update_t> {
  static bool plausible(const void* data, std::size_t size) {
    LcmFieldWalker w(data, size);
    std::int32_t count = 0;
    // hash, utime, resolution, frame_id, sequence, num_voxels of 16-byte voxel_t
    return w.skip(8 + 8 + 8) && w.skipString() && w.skip(8) && w.readCount(count, 16);
  }
};

template <>
struct MessagePrecheck<slamd::status_t> {
  static bool plausible(const void* data, std::size_t size) {
    LcmFieldWalker w(data, size);
    std::int32_t count = 0;
    // hash, utime, num_stages; each stage_status_t is at least a 4-byte name length + 76 bytes
    return w.skip(8 + 8) && w.readCount(count, 4 + 5 * 8 + 2 * 4 + 3 * 8);
  }
};

template <>
struct MessagePrecheck<slamd::keyframe_trajectory_t> {
  static bool plausible(const void* data, std::size_t size) {
    LcmFieldWalker w(data, size);
    std::int32_t count = 0;
    // hash, utime, sequence, frame_id, correction (3 + 4 doubles), num_loops,
    // num_relocalizations, optimization_ms, num_keyframes of 80-byte keyframe_pose_t
    return w.skip(8 + 8 + 8) && w.skipString() && w.skip(7 * 8 + 4 + 4 + 4) &&
           w.readCount(count, 3 * 8 + 7 * 8);
  }
};

template <>
struct MessagePrecheck<kinect::frame_msg_t> {
  static bool plausible(const void* data, std::size_t size) {
    LcmFieldWalker w(data, size);
    std::int32_t count = 0;
    // hash, timestamp; image: timestamp, width, height, nbytes, data, format;
    // depth: timestamp, width, height, nbytes, data, ...
    return w.skip(8 + 8) && w.skip(8 + 2 + 2) && w.readCount(count, 1) &&
           w.skip(static_cast<std::size_t>(count)) && w.skip(1) && w.skip(8 + 2 + 2) &&
           w.readCount(count, 1);
  }
};

}  // namespace slamd
