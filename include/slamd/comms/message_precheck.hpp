#pragma once
// Structural check of encoded LCM messages, run before lcm-gen's decoder sees the bytes.
//
// Why: LCM's generated C++ decoders trust the lengths they read. A string whose length field is
// zero or negative (INT32_MIN, say) is copied with assign(buffer, length - 1): a read of about
// 2^31 bytes past the buffer, which kills the process with one 23-byte packet. An array count is
// used to resize a vector before the buffer is checked to hold that many elements: one corrupt
// count allocates gigabytes. So every type slamd or its clients can decode is walked here, field
// by field, through its whole encoding: every string length must be at least 1 (the terminating
// NUL) and fit, with no NUL before its end; every array must fit; and the walk must end exactly
// at the end of the buffer. What passes is an encoding lcm-gen's encoder could have written.
// Only then does the generated decoder run. There is no default: decoding a type that has no
// walker below does not compile.
//
// Encodings (big-endian, as lcm-gen writes them): a top-level message starts with its 8-byte type
// hash; nested structs are encoded without one.

#include <cstdint>
#include <cstring>
#include <string>

#include "bot_core/pose_t.hpp"
#include "kinect/depth_msg_t.hpp"
#include "kinect/frame_msg_t.hpp"
#include "kinect/image_msg_t.hpp"
#include "slamd/command_t.hpp"
#include "slamd/keyframe_pose_t.hpp"
#include "slamd/keyframe_trajectory_t.hpp"
#include "slamd/odometry_t.hpp"
#include "slamd/plane_map_t.hpp"
#include "slamd/plane_t.hpp"
#include "slamd/pose_t.hpp"
#include "slamd/rgbd_frame_t.hpp"
#include "slamd/stage_status_t.hpp"
#include "slamd/status_t.hpp"
#include "slamd/vanishing_point_t.hpp"
#include "slamd/voxel_map_t.hpp"
#include "slamd/voxel_map_update_t.hpp"
#include "slamd/voxel_t.hpp"

namespace slamd {

/// Reads an LCM encoding field by field without allocating; any read past the end fails.
class LcmFieldWalker {
 public:
  LcmFieldWalker(const void* data, std::size_t size)
      : data_(static_cast<const std::uint8_t*>(data)), size_(data == nullptr ? 0 : size) {}

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
  /// An LCM string: int32 length including the terminating NUL (so at least 1), then the bytes,
  /// NUL only at the end (what the encoder writes: it measures strings with strlen).
  bool skipString() {
    std::int32_t length = 0;
    if (!readInt32(length)) return false;
    if (length < 1 || static_cast<std::size_t>(length) > size_ - pos_) return fail();
    const std::uint8_t* text = data_ + pos_;
    const auto last = static_cast<std::size_t>(length) - 1;
    if (text[last] != 0 || std::memchr(text, 0, last) != nullptr) return fail();
    pos_ += static_cast<std::size_t>(length);
    return true;
  }
  /// An int32 count of elements that each take at least `min_element_bytes`; fails when the rest
  /// of the buffer cannot hold them.
  bool readCount(std::int32_t& count, std::size_t min_element_bytes) {
    if (!readInt32(count)) return false;
    if (count < 0) return fail();
    if (static_cast<std::size_t>(count) * min_element_bytes > size_ - pos_) return fail();
    return true;
  }
  /// A count followed by that many bytes (a `byte data[count]` field).
  bool skipByteArray() {
    std::int32_t count = 0;
    return readCount(count, 1) && skip(static_cast<std::size_t>(count));
  }
  bool atEnd() const { return ok_ && pos_ == size_; }
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

/// The walker of one type: `static bool walk(LcmFieldWalker&)` over its fields (no hash). Every
/// decodable type has a specialisation; the primary template is never defined.
template <typename Message>
struct LcmLayout;

/// True when `data` holds exactly one well-formed encoding of `Message`, hash included (the hash
/// value itself is checked by the decoder).
template <typename Message>
bool plausibleEncoding(const void* data, std::size_t size) {
  LcmFieldWalker walker(data, size);
  return walker.skip(8) && LcmLayout<Message>::walk(walker) && walker.atEnd();
}

// Byte counts of fixed-size fields.
namespace lcm_bytes {
constexpr std::size_t kInt8 = 1;
constexpr std::size_t kInt16 = 2;
constexpr std::size_t kInt32 = 4;
constexpr std::size_t kFloat = 4;
constexpr std::size_t kInt64 = 8;
constexpr std::size_t kDouble = 8;
}  // namespace lcm_bytes

template <>
struct LcmLayout<bot_core::pose_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // utime; pos[3], vel[3], orientation[4], rotation_rate[3], accel[3]
    return w.skip(kInt64 + 16 * kDouble);
  }
};

template <>
struct LcmLayout<kinect::image_msg_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // timestamp, width, height, image_data_nbytes + image_data, image_data_format
    return w.skip(kInt64 + 2 * kInt16) && w.skipByteArray() && w.skip(kInt8);
  }
};

template <>
struct LcmLayout<kinect::depth_msg_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // timestamp, width, height, depth_data_nbytes + depth_data, depth_data_format, compression,
    // uncompressed_size
    return w.skip(kInt64 + 2 * kInt16) && w.skipByteArray() && w.skip(2 * kInt8 + kInt32);
  }
};

template <>
struct LcmLayout<kinect::frame_msg_t> {
  static bool walk(LcmFieldWalker& w) {
    return w.skip(lcm_bytes::kInt64) && LcmLayout<kinect::image_msg_t>::walk(w) &&
           LcmLayout<kinect::depth_msg_t>::walk(w);
  }
};

template <>
struct LcmLayout<slamd::command_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // utime, command, argument
    return w.skip(kInt64 + kInt8) && w.skipString();
  }
};

template <>
struct LcmLayout<slamd::keyframe_pose_t> {
  static constexpr std::size_t kBytes = 3 * lcm_bytes::kInt64 + 7 * lcm_bytes::kDouble;
  static bool walk(LcmFieldWalker& w) {
    // keyframe_id, utime, segment, position[3], orientation[4]
    return w.skip(kBytes);
  }
};

template <>
struct LcmLayout<slamd::keyframe_trajectory_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    std::int32_t count = 0;
    // utime, sequence, frame_id, correction_position[3], correction_orientation[4], num_loops,
    // num_relocalizations, optimization_ms, num_keyframes + keyframes
    return w.skip(2 * kInt64) && w.skipString() && w.skip(7 * kDouble + 2 * kInt32 + kFloat) &&
           w.readCount(count, LcmLayout<slamd::keyframe_pose_t>::kBytes) &&
           w.skip(static_cast<std::size_t>(count) * LcmLayout<slamd::keyframe_pose_t>::kBytes);
  }
};

template <>
struct LcmLayout<slamd::odometry_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // utime, prev_utime, translation[3], rotation[4], covariance[36], status, num_features,
    // num_matches, num_inliers, reprojection_error_px, is_keyframe, reference_keyframe_id
    return w.skip(2 * kInt64 + 43 * kDouble + kInt8 + 3 * kInt32 + kDouble + kInt8 + kInt64);
  }
};

template <>
struct LcmLayout<slamd::plane_t> {
  /// The fixed fields, before the vertices.
  static constexpr std::size_t kMinBytes =
      lcm_bytes::kInt64 + 5 * lcm_bytes::kDouble + 2 * lcm_bytes::kInt32;
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    std::int32_t count = 0;
    // id, normal[3], offset, area_m2, num_keyframes, num_vertices + vertices[num_vertices][3]
    return w.skip(kInt64 + 5 * kDouble + kInt32) && w.readCount(count, 3 * kDouble) &&
           w.skip(static_cast<std::size_t>(count) * 3 * kDouble);
  }
};

template <>
struct LcmLayout<slamd::plane_map_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    std::int32_t count = 0;
    // utime, frame_id, num_planes + planes
    if (!(w.skip(kInt64) && w.skipString() &&
          w.readCount(count, LcmLayout<slamd::plane_t>::kMinBytes))) {
      return false;
    }
    for (std::int32_t i = 0; i < count; ++i) {
      if (!LcmLayout<slamd::plane_t>::walk(w)) return false;
    }
    return true;
  }
};

template <>
struct LcmLayout<slamd::pose_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // utime, sequence, parent_frame, child_frame, position[3], orientation[4], covariance[36],
    // linear_velocity[3], angular_velocity[3], tracking_state, source
    return w.skip(2 * kInt64) && w.skipString() && w.skipString() &&
           w.skip(49 * kDouble + 2 * kInt8);
  }
};

template <>
struct LcmLayout<slamd::rgbd_frame_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // utime, sequence, frame_id, fx fy cx cy, width, height, distortion_model, distortion[5],
    // depth_scale, color_encoding, color_nbytes + color_data, depth_encoding,
    // depth_nbytes + depth_data
    return w.skip(2 * kInt64) && w.skipString() &&
           w.skip(4 * kDouble + 2 * kInt32 + kInt8 + 5 * kDouble + kDouble + kInt8) &&
           w.skipByteArray() && w.skip(kInt8) && w.skipByteArray();
  }
};

template <>
struct LcmLayout<slamd::stage_status_t> {
  /// The name's length field and NUL, then the fixed fields.
  static constexpr std::size_t kMinBytes = lcm_bytes::kInt32 + 1 + 4 * lcm_bytes::kDouble +
                                           2 * lcm_bytes::kInt32 + 3 * lcm_bytes::kInt64;
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // name, rate_hz, latency_p50/p95/p99_ms, queue_depth, queue_capacity, drops, errors,
    // processed
    return w.skipString() && w.skip(4 * kDouble + 2 * kInt32 + 3 * kInt64);
  }
};

template <>
struct LcmLayout<slamd::status_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    std::int32_t count = 0;
    // utime, num_stages + stages, end_to_end_p50/p95/p99_ms, tracking_state,
    // map_occupied_voxels, map_total_voxels, num_keyframes, num_loops, num_relocalizations,
    // memory_rss_mb, memory_limit_mb, memory_pressure, message
    if (!(w.skip(kInt64) && w.readCount(count, LcmLayout<slamd::stage_status_t>::kMinBytes))) {
      return false;
    }
    for (std::int32_t i = 0; i < count; ++i) {
      if (!LcmLayout<slamd::stage_status_t>::walk(w)) return false;
    }
    return w.skip(3 * kDouble + kInt8 + 2 * kInt64 + 3 * kInt32 + kDouble + kInt32 + kInt8) &&
           w.skipString();
  }
};

template <>
struct LcmLayout<slamd::vanishing_point_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // utime, pixel[2], pixel_covariance[4], direction_camera[3], num_supporting_lines,
    // landmark_id, accepted, mahalanobis_distance_sq
    return w.skip(kInt64 + 9 * kDouble + 2 * kInt32 + kInt8 + kDouble);
  }
};

template <>
struct LcmLayout<slamd::voxel_t> {
  static constexpr std::size_t kBytes = 4 * lcm_bytes::kFloat;
  static bool walk(LcmFieldWalker& w) { return w.skip(kBytes); }  // center[3], log_odds
};

template <>
struct LcmLayout<slamd::voxel_map_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    // utime, resolution, frame_id, update_sequence, num_bytes + data
    return w.skip(kInt64 + kDouble) && w.skipString() && w.skip(kInt64) && w.skipByteArray();
  }
};

template <>
struct LcmLayout<slamd::voxel_map_update_t> {
  static bool walk(LcmFieldWalker& w) {
    using namespace lcm_bytes;
    std::int32_t count = 0;
    // utime, resolution, frame_id, sequence, num_voxels + voxels
    return w.skip(kInt64 + kDouble) && w.skipString() && w.skip(kInt64) &&
           w.readCount(count, LcmLayout<slamd::voxel_t>::kBytes) &&
           w.skip(static_cast<std::size_t>(count) * LcmLayout<slamd::voxel_t>::kBytes);
  }
};

}  // namespace slamd
