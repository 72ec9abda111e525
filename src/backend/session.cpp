#include "slamd/backend/session.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <locale>
#include <map>
#include <ostream>
#include <set>
#include <sstream>
#include <system_error>
#include <unordered_map>
#include <unordered_set>

#include "slamd/common/binary_codec.hpp"
#include "slamd/common/file_io.hpp"
#include "slamd/common/log.hpp"

namespace slamd {

namespace {

namespace fs = std::filesystem;

constexpr char kKeyframesMagic[8] = {'S', 'L', 'A', 'M', 'D', 'K', 'F', 'S'};
constexpr char kGraphMagic[8] = {'S', 'L', 'A', 'M', 'D', 'G', 'R', 'F'};
constexpr const char* kManifestTag = "slamd-session";
constexpr const char* kGenerationPrefix = "generation-";

// Record sizes in bytes, for checking a count against the bytes that remain.
constexpr std::uint64_t kPoseBytes = kBinaryPoseBytes;
constexpr std::uint64_t kInformationBytes = 36 * 8;
// A keypoint: pt.x pt.y size angle response (floats), octave class_id (int32).
constexpr std::uint64_t kKeypointBytes = 5 * 4 + 2 * 4;
constexpr std::uint64_t kNodeBytes = 8 + kPoseBytes + 1;
constexpr std::uint64_t kEdgeBytes = 8 + 8 + kPoseBytes + kInformationBytes + 1;
constexpr std::uint64_t kCulledBytes = 8 + 8 + kPoseBytes + kInformationBytes;
constexpr std::uint64_t kRecordBytes = 8 + 8 + 8;
constexpr std::uint64_t kSegmentParentBytes = 8 + 8;
constexpr std::uint64_t kViewBytes = 8 + 8;
// The fixed part of a keyframe: ids and times, pose, intrinsics, median depth, num_with_depth,
// and the six counts or sizes that follow (keypoints, descriptor rows/cols/type, pixels, points,
// scale, gradients).
constexpr std::uint64_t kKeyframeFixedBytes =
    4 * 8 + kPoseBytes + (4 * 8 + 3 * 4 + 5 * 8) + 8 + 4 + 8 + 3 * 4 + 4 * 8;
// Generous bounds on what a real keyframe holds; they only reject nonsense.
constexpr std::int32_t kMaxDescriptorColumns = 1 << 16;
// Tolerance on R^T R - I for a pose to count as a rotation: far above what chains of products
// accumulate, far below a damaged matrix.
constexpr double kRotationTolerance = 1e-6;
// Focal lengths and principal points closer than this are the same camera (pixels).
constexpr double kCameraTolerancePx = 0.5;

/// Throws "session <path>: <problem>".
[[noreturn]] void refuse(const std::string& path, const std::string& problem) {
  throw SessionError("session " + path + ": " + problem);
}

std::string joinPath(const std::string& folder, const std::string& name) {
  return (fs::path(folder) / name).string();
}

// ---------------------------------------------------------------------------------------------
// Little-endian encoding (slamd/common/binary_codec.hpp) and what the session files add to it.

void writeInformation(LittleEndianWriter& out, const Matrix6d& m) {
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) out.f64(m(r, c));
  }
}

Matrix6d readInformation(LittleEndianReader& in) {
  Matrix6d m;
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) m(r, c) = in.f64();
  }
  return m;
}

// Reads one session file from memory. A problem is refused naming the file (fail()); a read past
// the end throws TruncatedBinaryError, which parseFile() refuses as "truncated (<where>)". Every
// count is checked with fits() before anything is allocated for it.
class SessionReader : public LittleEndianReader {
 public:
  SessionReader(const std::vector<std::uint8_t>& bytes, std::string path)
      : LittleEndianReader(bytes), path_(std::move(path)) {}

  [[noreturn]] void fail(const std::string& problem) const { refuse(path_, problem); }
  /// Checks the magic and the format version at the start of a file.
  void header(const char (&magic)[8]) {
    char found[8] = {};
    if (remaining() < sizeof(found)) fail("too short to be a slamd session file");
    raw(found, sizeof(found));
    if (std::memcmp(found, magic, sizeof(found)) != 0) {
      fail("bad magic (not written by slamd's session writer)");
    }
    setWhere("header");
    version_ = u32();
    if (version_ < kSessionOldestReadableVersion || version_ > kSessionFormatVersion) {
      fail("format version " + std::to_string(version_) + ", this slamd reads " +
           std::to_string(kSessionOldestReadableVersion) + " to " +
           std::to_string(kSessionFormatVersion));
    }
  }
  /// The file's format version (after header()).
  std::uint32_t version() const { return version_; }
  void expectEnd() const {
    if (remaining() != 0) {
      fail(std::to_string(remaining()) + " unexpected bytes after the last record");
    }
  }

 private:
  std::string path_;
  std::uint32_t version_ = 0;
};

/// Parses `bytes`, the file at `path`, with `parse(SessionReader&)`.
template <typename Parse>
void parseFile(const std::vector<std::uint8_t>& bytes, const std::string& path, Parse&& parse) {
  SessionReader in(bytes, path);
  try {
    parse(in);
  } catch (const TruncatedBinaryError& e) {
    refuse(path, e.what());
  }
}

std::string ofCount(std::uint64_t index, std::uint64_t count) {
  return std::to_string(index + 1) + " of " + std::to_string(count);
}

/// Reads a count of fixed-size records and checks they fit: a truncation names the first
/// incomplete record ("truncated (edge 17 of 40)").
std::uint64_t recordCount(SessionReader& in, const char* what, std::uint64_t record_bytes) {
  in.setWhere(std::string("count of ") + what + "s");
  const std::uint64_t count = in.u64();
  if (!in.fits(count, record_bytes)) {
    in.setWhere(std::string(what) + " " + ofCount(in.remaining() / record_bytes, count));
    in.truncated();
  }
  return count;
}

// ---------------------------------------------------------------------------------------------
// Checks shared by the writer and the readers.

bool allFinite(const double* values, int count) {
  for (int i = 0; i < count; ++i) {
    if (!std::isfinite(values[i])) return false;
  }
  return true;
}

bool isRigid(const SE3& T) {
  const Eigen::Matrix3d R = T.linear();
  const Eigen::Vector3d t = T.translation();
  if (!allFinite(R.data(), 9) || !allFinite(t.data(), 3)) return false;
  return (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <
             kRotationTolerance &&
         R.determinant() > 0.0;
}

bool isFinite(const Matrix6d& m) { return allFinite(m.data(), 36); }

bool isKnownEdgeKind(int kind) {
  return kind >= static_cast<int>(EdgeKind::kOdometry) &&
         kind <= static_cast<int>(EdgeKind::kRelocalization);
}

/// OpenCV element types a descriptor matrix may have: depth CV_8U..CV_64F, 1 to 4 channels.
bool isDescriptorType(int type) {
  return type >= 0 && CV_MAT_DEPTH(type) <= CV_64F && CV_MAT_CN(type) <= 4 &&
         type == CV_MAKETYPE(CV_MAT_DEPTH(type), CV_MAT_CN(type));
}

/// Empty when the keyframe can be saved and read back; otherwise the problem.
std::string keyframeProblem(const Keyframe& keyframe) {
  const FeatureSet& f = keyframe.features;
  const std::size_t n = f.keypoints.size();
  auto sizes = [n](const char* what, std::size_t size) {
    return std::to_string(size) + " " + what + " for " + std::to_string(n) + " keypoints";
  };
  if (keyframe.id < 0) return "negative id " + std::to_string(keyframe.id);
  if (keyframe.segment < 0) return "negative segment " + std::to_string(keyframe.segment);
  if (!isRigid(keyframe.T_world_camera)) return "T_world_camera is not a finite rigid transform";
  const CameraIntrinsics& K = keyframe.intrinsics;
  if (K.distortion_model != DistortionModel::kNone &&
      K.distortion_model != DistortionModel::kPlumbBob) {
    return "unknown distortion model " + std::to_string(static_cast<int>(K.distortion_model));
  }
  const std::string camera = K.validationError();
  if (!camera.empty()) return "intrinsics: " + camera;
  if (!std::isfinite(keyframe.median_depth_m) || keyframe.median_depth_m < 0.0) {
    return "median depth is not a finite non-negative number";
  }
  if (f.num_with_depth < 0 || static_cast<std::size_t>(f.num_with_depth) > n) {
    return "num_with_depth " + std::to_string(f.num_with_depth) + " for " + std::to_string(n) +
           " keypoints";
  }
  if (n > static_cast<std::size_t>(std::numeric_limits<int>::max())) return "too many keypoints";
  if (!f.descriptors.empty()) {
    if (!isDescriptorType(f.descriptors.type()) || f.descriptors.dims != 2) {
      return "unsupported descriptor type " + std::to_string(f.descriptors.type());
    }
    if (static_cast<std::size_t>(f.descriptors.rows) != n) {
      return sizes("descriptor rows", static_cast<std::size_t>(f.descriptors.rows));
    }
    if (f.descriptors.cols > kMaxDescriptorColumns) {
      return std::to_string(f.descriptors.cols) + " descriptor columns";
    }
  }
  if (f.pixels.size() != n) return sizes("pixels", f.pixels.size());
  if (f.points.size() != n) return sizes("points", f.points.size());
  if (!f.scale.empty() && f.scale.size() != n) return sizes("scales", f.scale.size());
  if (!f.inverse_depth_gradient.empty() && f.inverse_depth_gradient.size() != n) {
    return sizes("inverse-depth gradients", f.inverse_depth_gradient.size());
  }
  return {};
}

/// Follows `next` (key -> next key) from each of `starts` in turn; returns the first start whose
/// path comes back to a key already on it (a link from a key to itself ends a path, as a
/// union-find root), or -1 when every path ends. Linear time: each key is walked once.
std::int64_t firstOnCycle(const std::unordered_map<std::int64_t, std::int64_t>& next,
                          const std::vector<std::int64_t>& starts) {
  enum class Mark { kOnPath, kEnds };
  std::unordered_map<std::int64_t, Mark> marks;
  std::vector<std::int64_t> path;
  for (const std::int64_t start : starts) {
    path.clear();
    for (std::int64_t key = start;;) {
      const auto mark = marks.find(key);
      if (mark != marks.end()) {
        if (mark->second == Mark::kOnPath) return start;
        break;
      }
      const auto link = next.find(key);
      if (link == next.end() || link->second == key) break;
      marks[key] = Mark::kOnPath;
      path.push_back(key);
      key = link->second;
    }
    for (const std::int64_t key : path) marks[key] = Mark::kEnds;
  }
  return -1;
}

/// A problem with a snapshot, and the file it is reported against.
struct SnapshotProblem {
  const char* file = kSessionGraphFile;
  std::string problem;  ///< empty: consistent
};

SnapshotProblem graphFile(std::string problem) { return {kSessionGraphFile, std::move(problem)}; }

/// The consistency of a whole snapshot (the file comment of session.hpp lists the rules).
SnapshotProblem snapshotProblem(const BackendSnapshot& s) {
  std::int64_t max_id = -1;
  std::int64_t max_segment = -1;
  std::unordered_set<std::int64_t> keyframe_ids;
  for (std::size_t i = 0; i < s.keyframes.size(); ++i) {
    const std::string where = "keyframe " + ofCount(i, s.keyframes.size());
    if (!s.keyframes[i]) return {kSessionKeyframesFile, where + " is null"};
    const Keyframe& keyframe = *s.keyframes[i];
    const std::string problem = keyframeProblem(keyframe);
    if (!problem.empty()) {
      return {kSessionKeyframesFile,
              where + " (id " + std::to_string(keyframe.id) + "): " + problem};
    }
    if (!keyframe_ids.insert(keyframe.id).second) {
      return {kSessionKeyframesFile, "keyframe id " + std::to_string(keyframe.id) + " twice"};
    }
    max_id = std::max(max_id, keyframe.id);
    max_segment = std::max(max_segment, keyframe.segment);
  }

  std::unordered_set<std::int64_t> node_ids;
  for (const BackendSnapshot::Node& node : s.nodes) {
    const std::string name = "node " + std::to_string(node.id);
    if (!node_ids.insert(node.id).second) return graphFile(name + " twice");
    if (keyframe_ids.count(node.id) == 0) {
      return graphFile(name + " has no keyframe in " + kSessionKeyframesFile);
    }
    if (!isRigid(node.T_world_camera)) {
      return graphFile(name + ": T_world_camera is not a finite rigid transform");
    }
  }
  for (const KeyframePtr& keyframe : s.keyframes) {
    if (node_ids.count(keyframe->id) == 0) {
      return graphFile("keyframe " + std::to_string(keyframe->id) + " of " + kSessionKeyframesFile +
                       " is not a node");
    }
  }

  for (std::size_t i = 0; i < s.edges.size(); ++i) {
    const PoseGraphEdge& edge = s.edges[i];
    const std::string name = "edge " + ofCount(i, s.edges.size()) + " (" +
                             std::to_string(edge.from_id) + " -> " + std::to_string(edge.to_id) +
                             ")";
    if (!isKnownEdgeKind(static_cast<int>(edge.kind))) {
      return graphFile(name + ": unknown kind " + std::to_string(static_cast<int>(edge.kind)));
    }
    if (node_ids.count(edge.from_id) == 0 || node_ids.count(edge.to_id) == 0) {
      return graphFile(name + " names a missing node");
    }
    if (edge.from_id == edge.to_id) return graphFile(name + " joins a node to itself");
    if (!isRigid(edge.T_from_to)) return graphFile(name + ": T_from_to is not a rigid transform");
    if (!isFinite(edge.information)) return graphFile(name + ": information is not finite");
  }

  std::unordered_map<std::int64_t, std::int64_t> anchor_of;
  for (const CulledKeyframeRecord& culled : s.culled) {
    const std::string name = "culled keyframe " + std::to_string(culled.id);
    if (culled.id < 0) return graphFile(name + ": negative id");
    if (node_ids.count(culled.id) != 0) return graphFile(name + " is also a node");
    if (!anchor_of.emplace(culled.id, culled.anchor_id).second) return graphFile(name + " twice");
    if (!isRigid(culled.T_anchor_keyframe)) {
      return graphFile(name + ": T_anchor_keyframe is not a rigid transform");
    }
    if (!isFinite(culled.information)) return graphFile(name + ": information is not finite");
    max_id = std::max(max_id, culled.id);
  }
  std::vector<std::int64_t> culled_ids;
  for (const CulledKeyframeRecord& culled : s.culled) {
    if (node_ids.count(culled.anchor_id) == 0 && anchor_of.count(culled.anchor_id) == 0) {
      return graphFile("culled keyframe " + std::to_string(culled.id) + ": anchor " +
                       std::to_string(culled.anchor_id) +
                       " is neither a node nor a culled keyframe");
    }
    culled_ids.push_back(culled.id);
  }
  // Every anchor exists, so a chain of anchors either ends at a node or goes round a cycle.
  if (const std::int64_t id = firstOnCycle(anchor_of, culled_ids); id >= 0) {
    return graphFile("culled keyframe " + std::to_string(id) + ": its anchors form a cycle");
  }

  std::unordered_set<std::int64_t> record_ids;
  for (const KeyframeRecord& record : s.records) {
    const std::string name = "record of keyframe " + std::to_string(record.id);
    if (!record_ids.insert(record.id).second) return graphFile(name + " twice");
    if (node_ids.count(record.id) == 0 && anchor_of.count(record.id) == 0) {
      return graphFile(name + ": no such keyframe or culled keyframe");
    }
    if (record.segment < 0) return graphFile(name + ": negative segment");
    if (!std::isfinite(record.path_length_m) || record.path_length_m < 0.0) {
      return graphFile(name + ": path length is not a finite non-negative number");
    }
    max_segment = std::max(max_segment, record.segment);
  }

  std::unordered_map<std::int64_t, std::int64_t> parent_of;
  for (const auto& [segment, parent] : s.segment_parents) {
    if (segment < 0 || parent < 0) return graphFile("negative segment in segment_parents");
    if (!parent_of.emplace(segment, parent).second) {
      return graphFile("segment " + std::to_string(segment) + " has two parents");
    }
    max_segment = std::max({max_segment, segment, parent});
  }
  std::vector<std::int64_t> child_segments;
  for (const auto& link : s.segment_parents) child_segments.push_back(link.first);
  if (const std::int64_t segment = firstOnCycle(parent_of, child_segments); segment >= 0) {
    return graphFile("segment " + std::to_string(segment) + ": its parents form a cycle");
  }

  std::set<std::pair<std::int64_t, std::int64_t>> views;
  for (const auto& [a, b] : s.views) {
    const std::string name = "view " + std::to_string(a) + " - " + std::to_string(b);
    if (node_ids.count(a) == 0 || node_ids.count(b) == 0) {
      return graphFile(name + ": not two keyframes of the graph");
    }
    if (a >= b) return graphFile(name + ": not lower id first");
    if (!views.emplace(a, b).second) return graphFile(name + " twice");
  }

  if (s.first_segment < 0) return graphFile("negative first segment");
  if (s.next_keyframe_id <= max_id) {
    return graphFile("next keyframe id " + std::to_string(s.next_keyframe_id) +
                     " is not above keyframe id " + std::to_string(max_id));
  }
  if (s.next_segment <= max_segment) {
    return graphFile("next segment " + std::to_string(s.next_segment) + " is not above segment " +
                     std::to_string(max_segment));
  }
  if (s.num_loops < 0 || s.num_local_edges < 0 || s.num_relocalizations < 0) {
    return graphFile("negative counter");
  }
  return {};
}

// ---------------------------------------------------------------------------------------------
// keyframes.bin and graph.bin.

void writeDescriptors(LittleEndianWriter& out, const cv::Mat& descriptors) {
  if (descriptors.empty()) {
    out.i32(0);
    out.i32(0);
    out.i32(0);
    return;
  }
  out.i32(descriptors.rows);
  out.i32(descriptors.cols);
  out.i32(descriptors.type());
  const std::size_t element = descriptors.elemSize1();
  const std::size_t values = static_cast<std::size_t>(descriptors.cols) * descriptors.channels();
  for (int r = 0; r < descriptors.rows; ++r) {
    const std::uint8_t* row = descriptors.ptr<std::uint8_t>(r);
    if (element == 1) {
      out.raw(row, values);
      continue;
    }
    for (std::size_t v = 0; v < values; ++v) {
      const std::uint8_t* p = row + v * element;
      if (element == 2) {
        std::uint16_t x = 0;
        std::memcpy(&x, p, 2);
        out.u16(x);
      } else if (element == 4) {
        std::uint32_t x = 0;
        std::memcpy(&x, p, 4);
        out.u32(x);
      } else {
        std::uint64_t x = 0;
        std::memcpy(&x, p, 8);
        out.u64(x);
      }
    }
  }
}

cv::Mat readDescriptors(SessionReader& in, std::uint64_t keypoints) {
  const std::int32_t rows = in.i32();
  const std::int32_t cols = in.i32();
  const std::int32_t type = in.i32();
  if (rows == 0 && cols == 0) return {};
  if (!isDescriptorType(type))
    in.fail(in.where() + ": unsupported descriptor type " + std::to_string(type));
  if (rows < 0 || static_cast<std::uint64_t>(rows) != keypoints) {
    in.fail(in.where() + ": " + std::to_string(rows) + " descriptor rows for " +
            std::to_string(keypoints) + " keypoints");
  }
  if (cols < 1 || cols > kMaxDescriptorColumns) {
    in.fail(in.where() + ": " + std::to_string(cols) + " descriptor columns");
  }
  const std::size_t element = CV_ELEM_SIZE1(type);
  const std::size_t values = static_cast<std::size_t>(cols) * CV_MAT_CN(type);
  if (!in.fits(static_cast<std::uint64_t>(rows), values * element)) {
    in.setWhere(in.where() + ", descriptors");
    in.truncated();
  }
  cv::Mat descriptors(rows, cols, type);
  for (int r = 0; r < rows; ++r) {
    std::uint8_t* row = descriptors.ptr<std::uint8_t>(r);
    if (element == 1) {
      in.raw(row, values);
      continue;
    }
    for (std::size_t v = 0; v < values; ++v) {
      std::uint8_t* p = row + v * element;
      if (element == 2) {
        const std::uint16_t x = in.u16();
        std::memcpy(p, &x, 2);
      } else if (element == 4) {
        const std::uint32_t x = in.u32();
        std::memcpy(p, &x, 4);
      } else {
        const std::uint64_t x = in.u64();
        std::memcpy(p, &x, 8);
      }
    }
  }
  return descriptors;
}

void writeKeyframe(LittleEndianWriter& out, const Keyframe& keyframe) {
  out.i64(keyframe.id);
  out.i64(keyframe.segment);
  out.i64(keyframe.utime);
  out.i64(keyframe.frame_sequence);
  writePose(out, keyframe.T_world_camera);
  const CameraIntrinsics& K = keyframe.intrinsics;
  out.f64(K.fx);
  out.f64(K.fy);
  out.f64(K.cx);
  out.f64(K.cy);
  out.i32(K.width);
  out.i32(K.height);
  out.i32(static_cast<std::int32_t>(K.distortion_model));
  for (double d : K.distortion) out.f64(d);
  out.f64(keyframe.median_depth_m);
  const FeatureSet& f = keyframe.features;
  out.i32(f.num_with_depth);
  out.u64(f.keypoints.size());
  for (const cv::KeyPoint& k : f.keypoints) {
    out.f32(k.pt.x);
    out.f32(k.pt.y);
    out.f32(k.size);
    out.f32(k.angle);
    out.f32(k.response);
    out.i32(k.octave);
    out.i32(k.class_id);
  }
  writeDescriptors(out, f.descriptors);
  out.u64(f.pixels.size());
  for (const Eigen::Vector2d& p : f.pixels) {
    out.f64(p.x());
    out.f64(p.y());
  }
  out.u64(f.points.size());
  for (const Eigen::Vector3d& p : f.points) {
    out.f64(p.x());
    out.f64(p.y());
    out.f64(p.z());
  }
  out.u64(f.scale.size());
  for (float v : f.scale) out.f32(v);
  out.u64(f.inverse_depth_gradient.size());
  for (const Eigen::Vector2d& g : f.inverse_depth_gradient) {
    out.f64(g.x());
    out.f64(g.y());
  }
}

/// The count of a per-keypoint vector, checked against the bytes that remain.
std::uint64_t vectorCount(SessionReader& in, const std::string& where, const char* what,
                          std::uint64_t element_bytes) {
  const std::uint64_t count = in.u64();
  if (!in.fits(count, element_bytes)) {
    in.setWhere(where + ", " + what);
    in.truncated();
  }
  return count;
}

std::shared_ptr<Keyframe> readKeyframe(SessionReader& in, std::uint64_t index,
                                       std::uint64_t count) {
  const std::string where = "keyframe " + ofCount(index, count);
  in.setWhere(where);
  if (in.remaining() < kKeyframeFixedBytes) in.truncated();
  auto keyframe = std::make_shared<Keyframe>();
  keyframe->id = in.i64();
  keyframe->segment = in.i64();
  keyframe->utime = in.i64();
  keyframe->frame_sequence = in.i64();
  keyframe->T_world_camera = readPose(in);
  CameraIntrinsics& K = keyframe->intrinsics;
  K.fx = in.f64();
  K.fy = in.f64();
  K.cx = in.f64();
  K.cy = in.f64();
  K.width = in.i32();
  K.height = in.i32();
  const std::int32_t model = in.i32();
  if (model != static_cast<std::int32_t>(DistortionModel::kNone) &&
      model != static_cast<std::int32_t>(DistortionModel::kPlumbBob)) {
    in.fail(where + ": unknown distortion model " + std::to_string(model));
  }
  K.distortion_model = static_cast<DistortionModel>(model);
  for (double& d : K.distortion) d = in.f64();
  keyframe->median_depth_m = in.f64();

  FeatureSet& f = keyframe->features;
  f.num_with_depth = in.i32();
  const std::uint64_t n = vectorCount(in, where, "keypoints", kKeypointBytes);
  if (n > static_cast<std::uint64_t>(std::numeric_limits<int>::max())) {
    in.fail(where + ": " + std::to_string(n) + " keypoints");
  }
  f.keypoints.resize(static_cast<std::size_t>(n));
  for (cv::KeyPoint& k : f.keypoints) {
    k.pt.x = in.f32();
    k.pt.y = in.f32();
    k.size = in.f32();
    k.angle = in.f32();
    k.response = in.f32();
    k.octave = in.i32();
    k.class_id = in.i32();
  }
  f.descriptors = readDescriptors(in, n);
  f.pixels.resize(static_cast<std::size_t>(vectorCount(in, where, "pixels", 16)));
  for (Eigen::Vector2d& p : f.pixels) {
    p.x() = in.f64();
    p.y() = in.f64();
  }
  f.points.resize(static_cast<std::size_t>(vectorCount(in, where, "points", 24)));
  for (Eigen::Vector3d& p : f.points) {
    p.x() = in.f64();
    p.y() = in.f64();
    p.z() = in.f64();
  }
  f.scale.resize(static_cast<std::size_t>(vectorCount(in, where, "scales", 4)));
  for (float& v : f.scale) v = in.f32();
  f.inverse_depth_gradient.resize(
      static_cast<std::size_t>(vectorCount(in, where, "inverse-depth gradients", 16)));
  for (Eigen::Vector2d& g : f.inverse_depth_gradient) {
    g.x() = in.f64();
    g.y() = in.f64();
  }
  return keyframe;
}

std::string graphBytes(const BackendSnapshot& s) {
  std::string bytes;
  LittleEndianWriter out(bytes);
  out.raw(kGraphMagic, sizeof(kGraphMagic));
  out.u32(kSessionFormatVersion);
  out.i64(s.first_segment);
  out.i64(s.next_keyframe_id);
  out.i64(s.next_segment);
  out.i64(s.num_loops);
  out.i64(s.num_local_edges);
  out.i64(s.num_relocalizations);
  out.u64(s.nodes.size());
  for (const BackendSnapshot::Node& node : s.nodes) {
    out.i64(node.id);
    writePose(out, node.T_world_camera);
    out.u8(node.fixed ? 1 : 0);
  }
  out.u64(s.edges.size());
  for (const PoseGraphEdge& edge : s.edges) {
    out.i64(edge.from_id);
    out.i64(edge.to_id);
    writePose(out, edge.T_from_to);
    writeInformation(out, edge.information);
    out.u8(static_cast<std::uint8_t>(edge.kind));
  }
  out.u64(s.culled.size());
  for (const CulledKeyframeRecord& culled : s.culled) {
    out.i64(culled.id);
    out.i64(culled.anchor_id);
    writePose(out, culled.T_anchor_keyframe);
    writeInformation(out, culled.information);
  }
  out.u64(s.records.size());
  for (const KeyframeRecord& record : s.records) {
    out.i64(record.id);
    out.i64(record.segment);
    out.f64(record.path_length_m);
  }
  out.u64(s.segment_parents.size());
  for (const auto& [segment, parent] : s.segment_parents) {
    out.i64(segment);
    out.i64(parent);
  }
  out.u64(s.views.size());
  for (const auto& [a, b] : s.views) {
    out.i64(a);
    out.i64(b);
  }
  return bytes;
}

void readGraph(SessionReader& in, BackendSnapshot& s) {
  in.header(kGraphMagic);
  s.first_segment = in.i64();
  s.next_keyframe_id = in.i64();
  s.next_segment = in.i64();
  s.num_loops = in.i64();
  s.num_local_edges = in.i64();
  s.num_relocalizations = in.i64();

  const std::uint64_t num_nodes = recordCount(in, "node", kNodeBytes);
  s.nodes.resize(static_cast<std::size_t>(num_nodes));
  for (std::uint64_t i = 0; i < num_nodes; ++i) {
    BackendSnapshot::Node& node = s.nodes[static_cast<std::size_t>(i)];
    node.id = in.i64();
    node.T_world_camera = readPose(in);
    const std::uint8_t fixed = in.u8();
    if (fixed > 1)
      in.fail("node " + ofCount(i, num_nodes) + ": fixed flag " + std::to_string(fixed));
    node.fixed = fixed == 1;
  }
  const std::uint64_t num_edges = recordCount(in, "edge", kEdgeBytes);
  s.edges.resize(static_cast<std::size_t>(num_edges));
  for (std::uint64_t i = 0; i < num_edges; ++i) {
    PoseGraphEdge& edge = s.edges[static_cast<std::size_t>(i)];
    edge.from_id = in.i64();
    edge.to_id = in.i64();
    edge.T_from_to = readPose(in);
    edge.information = readInformation(in);
    const std::uint8_t kind = in.u8();
    if (!isKnownEdgeKind(kind)) {
      in.fail("edge " + ofCount(i, num_edges) + ": unknown kind " + std::to_string(kind));
    }
    edge.kind = static_cast<EdgeKind>(kind);
  }
  const std::uint64_t num_culled = recordCount(in, "culled keyframe", kCulledBytes);
  s.culled.resize(static_cast<std::size_t>(num_culled));
  for (CulledKeyframeRecord& culled : s.culled) {
    culled.id = in.i64();
    culled.anchor_id = in.i64();
    culled.T_anchor_keyframe = readPose(in);
    culled.information = readInformation(in);
  }
  const std::uint64_t num_records = recordCount(in, "keyframe record", kRecordBytes);
  s.records.resize(static_cast<std::size_t>(num_records));
  for (KeyframeRecord& record : s.records) {
    record.id = in.i64();
    record.segment = in.i64();
    record.path_length_m = in.f64();
  }
  const std::uint64_t num_links = recordCount(in, "segment parent", kSegmentParentBytes);
  s.segment_parents.resize(static_cast<std::size_t>(num_links));
  for (auto& [segment, parent] : s.segment_parents) {
    segment = in.i64();
    parent = in.i64();
  }
  if (in.version() >= 2) {
    const std::uint64_t num_views = recordCount(in, "view", kViewBytes);
    s.views.resize(static_cast<std::size_t>(num_views));
    for (auto& [a, b] : s.views) {
      a = in.i64();
      b = in.i64();
    }
  }
  in.expectEnd();
}

// ---------------------------------------------------------------------------------------------
// Files and folders.

std::string hex64(std::uint64_t value) {
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(value));
  return text;
}

/// A plain file name of a generation: no folder part, nothing the manifest's lines cannot hold.
bool isPlainFileName(const std::string& name) {
  if (name.empty() || name.size() > 255 || name == "." || name == "..") return false;
  for (char c : name) {
    if (c == '/' || c == '\\' || static_cast<unsigned char>(c) <= ' ' ||
        static_cast<unsigned char>(c) >= 0x7f) {
      return false;
    }
  }
  return true;
}

/// The number of a generation folder name ("generation-000007" -> 7); -1 for any other name.
std::int64_t generationNumber(const std::string& name) {
  const std::string prefix = kGenerationPrefix;
  if (name.size() <= prefix.size() || name.size() > prefix.size() + 15 ||
      name.compare(0, prefix.size(), prefix) != 0) {
    return -1;
  }
  std::int64_t number = 0;
  for (std::size_t i = prefix.size(); i < name.size(); ++i) {
    if (name[i] < '0' || name[i] > '9') return -1;
    number = number * 10 + (name[i] - '0');
  }
  return number;
}

std::string generationName(std::int64_t number) {
  char text[32];
  std::snprintf(text, sizeof(text), "%s%06lld", kGenerationPrefix, static_cast<long long>(number));
  return text;
}

/// Refuses a path that is missing or not a regular file (a FIFO would block the reader).
void requireRegularFile(const std::string& path) {
  std::error_code error;
  const fs::file_status status = fs::status(path, error);
  if (status.type() == fs::file_type::not_found) refuse(path, "missing");
  if (error) refuse(path, "cannot be read: " + error.message());
  if (status.type() != fs::file_type::regular) refuse(path, "not a regular file");
}

/// The whole of a regular file; "missing", "empty" (unless allowed) and the other problems are
/// refused naming it.
std::vector<std::uint8_t> readWhole(const std::string& path, bool allow_empty) {
  requireRegularFile(path);
  std::error_code error;
  const std::uintmax_t size = fs::file_size(path, error);
  if (!error && size == 0) {
    if (!allow_empty) refuse(path, "empty");
    return {};
  }
  std::vector<std::uint8_t> bytes;
  std::string why;
  if (!readFileBytes(path, bytes, why)) refuse(path, "cannot be read");
  return bytes;
}

/// Size and checksum of a file, read in pieces (a map can be large).
void checksumFile(const std::string& path, std::uint64_t& size, std::uint64_t& checksum) {
  requireRegularFile(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) refuse(path, "cannot be opened");
  std::vector<char> buffer(1 << 20);
  size = 0;
  checksum = kFnv1a64Basis;
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const auto got = static_cast<std::size_t>(in.gcount());
    checksum = fnv1a64(buffer.data(), got, checksum);
    size += got;
  }
  if (in.bad()) refuse(path, "read error");
}

void fsyncFolder(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0)
    throw SessionError("cannot save session: cannot open " + path + ": " + std::strerror(errno));
  const bool synced = ::fsync(fd) == 0;
  const int saved = errno;
  ::close(fd);
  if (!synced) {
    throw SessionError("cannot save session: fsync of " + path +
                       " failed: " + std::strerror(saved));
  }
}

/// Passes what is written on to `out`, counting its size and checksum on the way.
class CountingBuffer : public std::streambuf {
 public:
  explicit CountingBuffer(std::ostream& out) : out_(out) {}
  std::uint64_t size = 0;
  std::uint64_t checksum = kFnv1a64Basis;

 protected:
  std::streamsize xsputn(const char* data, std::streamsize count) override {
    checksum = fnv1a64(data, static_cast<std::size_t>(count), checksum);
    size += static_cast<std::uint64_t>(count);
    out_.write(data, count);
    return out_ ? count : 0;
  }
  int_type overflow(int_type ch) override {
    if (traits_type::eq_int_type(ch, traits_type::eof())) return traits_type::not_eof(ch);
    const char c = traits_type::to_char_type(ch);
    return xsputn(&c, 1) == 1 ? ch : traits_type::eof();
  }

 private:
  std::ostream& out_;
};

/// The generation CURRENT names (refused when missing or not a generation folder's name).
std::string readCurrent(const std::string& dir) {
  const std::string path = joinPath(dir, kSessionCurrentFile);
  std::error_code error;
  if (!fs::exists(fs::status(path, error))) {
    refuse(path, "missing (not a session folder, or no save of it completed)");
  }
  const std::vector<std::uint8_t> bytes = readWhole(path, false);
  std::string name(bytes.begin(), bytes.end());
  if (!name.empty() && name.back() == '\n') name.pop_back();
  if (generationNumber(name) < 0) {
    refuse(path, "does not name a generation folder ('" + printableExcerpt(name) + "')");
  }
  return name;
}

// ---------------------------------------------------------------------------------------------
// manifest.txt.

struct ManifestFile {
  std::string name;
  std::uint64_t size = 0;
  std::uint64_t checksum = 0;
};

struct Manifest {
  SessionInfo info;
  std::vector<ManifestFile> files;
};

std::string formatDouble(double value) {
  std::ostringstream out;
  out.imbue(std::locale::classic());
  out.precision(17);
  out << value;
  return out.str();
}

/// An extent for the manifest; a non-finite coordinate (an empty map's bounds) is written as 0,
/// so that the summary never makes a session unreadable.
std::string formatVector(const Eigen::Vector3d& v) {
  auto finite = [](double x) { return formatDouble(std::isfinite(x) ? x : 0.0); };
  return finite(v.x()) + " " + finite(v.y()) + " " + finite(v.z());
}

const char* distortionModelName(DistortionModel model) {
  return model == DistortionModel::kPlumbBob ? "plumb_bob" : "none";
}

std::string manifestText(const SessionInfo& info, const std::vector<ManifestFile>& files) {
  std::ostringstream out;
  out.imbue(std::locale::classic());
  std::string created_by = info.created_by;
  for (char& c : created_by) {
    if (static_cast<unsigned char>(c) < ' ' || c == 0x7f) c = ' ';
  }
  const CameraIntrinsics& K = info.camera;
  out << kManifestTag << ' ' << kSessionFormatVersion << '\n'
      << "created_utime " << info.created_utime << '\n'
      << "created_by " << created_by << '\n'
      << "camera_width " << K.width << '\n'
      << "camera_height " << K.height << '\n'
      << "camera_fx " << formatDouble(K.fx) << '\n'
      << "camera_fy " << formatDouble(K.fy) << '\n'
      << "camera_cx " << formatDouble(K.cx) << '\n'
      << "camera_cy " << formatDouble(K.cy) << '\n'
      << "camera_distortion_model " << distortionModelName(K.distortion_model) << '\n'
      << "camera_distortion";
  for (double d : K.distortion) out << ' ' << formatDouble(d);
  out << '\n'
      << "keyframes " << info.keyframes << '\n'
      << "culled_keyframes " << info.culled_keyframes << '\n'
      << "landmarks " << info.landmarks << '\n'
      << "edges " << info.edges << '\n'
      << "segments " << info.segments << '\n'
      << "loops " << info.loops << '\n'
      << "map_voxels " << info.map_voxels << '\n'
      << "keyframe_min_m " << formatVector(info.keyframe_min_m) << '\n'
      << "keyframe_max_m " << formatVector(info.keyframe_max_m) << '\n'
      << "map_min_m " << formatVector(info.map_min_m) << '\n'
      << "map_max_m " << formatVector(info.map_max_m) << '\n';
  for (const ManifestFile& file : files) {
    out << "file " << file.name << ' ' << file.size << ' ' << hex64(file.checksum) << '\n';
  }
  std::string text = out.str();
  text += "checksum " + hex64(fnv1a64(text.data(), text.size())) + "\n";
  return text;
}

/// Parses the values of one manifest line; refuses the manifest on anything else.
class ManifestLine {
 public:
  ManifestLine(const std::string& path, int number, const std::string& key,
               const std::string& value)
      : path_(path), number_(number), key_(key), in_(value) {
    in_.imbue(std::locale::classic());
  }
  [[noreturn]] void fail(const std::string& problem) const {
    refuse(path_, "line " + std::to_string(number_) + " (" + key_ + "): " + problem);
  }
  template <typename T>
  T next() {
    T value{};
    if (!(in_ >> value)) fail("expected a number");
    return value;
  }
  std::string word() {
    std::string value;
    if (!(in_ >> value)) fail("missing value");
    return value;
  }
  std::uint64_t hex() {
    const std::string text = word();
    if (text.size() != 16 || text.find_first_not_of("0123456789abcdef") != std::string::npos) {
      fail("expected 16 hex digits");
    }
    return std::stoull(text, nullptr, 16);
  }
  Eigen::Vector3d vector() {
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v(i) = next<double>();
    return v;
  }
  void end() {
    std::string extra;
    if (in_ >> extra) fail("unexpected '" + printableExcerpt(extra) + "'");
  }

 private:
  const std::string& path_;
  int number_;
  std::string key_;
  std::istringstream in_;
};

Manifest parseManifest(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  const std::string text(bytes.begin(), bytes.end());
  // The version first: a newer slamd may have changed everything after it.
  const std::size_t first_end = text.find('\n');
  const std::string first = text.substr(0, first_end);
  const std::string tag = std::string(kManifestTag) + " ";
  std::uint64_t version = 0;
  bool version_ok = first.size() > tag.size() && first.size() <= tag.size() + 9 &&
                    first.compare(0, tag.size(), tag) == 0;
  for (std::size_t i = tag.size(); version_ok && i < first.size(); ++i) {
    if (first[i] < '0' || first[i] > '9') version_ok = false;
    version = version * 10 + static_cast<std::uint64_t>(first[i] - '0');
  }
  if (!version_ok || first_end == std::string::npos) {
    refuse(path, "not a slamd session manifest (first line '" + printableExcerpt(first) + "')");
  }
  if (version > kSessionFormatVersion) {
    refuse(path, "the session was made by a newer slamd (format " + std::to_string(version) +
                     ", this slamd reads " + std::to_string(kSessionFormatVersion) + ")");
  }
  if (version < kSessionOldestReadableVersion) {
    refuse(path, "the session has format " + std::to_string(version) +
                     ", older than this slamd reads (" +
                     std::to_string(kSessionOldestReadableVersion) + ")");
  }

  // The checksum line closes the file and covers every byte before it.
  const std::string checksum_tag = "checksum ";
  if (text.empty() || text.back() != '\n') refuse(path, "truncated (no final checksum line)");
  const std::size_t last_start = text.rfind('\n', text.size() - 2) + 1;
  const std::string last = text.substr(last_start, text.size() - 1 - last_start);
  if (last.compare(0, checksum_tag.size(), checksum_tag) != 0) {
    refuse(path, "truncated (no final checksum line)");
  }
  {
    ManifestLine line(path, 0, "checksum", last.substr(checksum_tag.size()));
    const std::uint64_t stated = line.hex();
    line.end();
    if (stated != fnv1a64(text.data(), last_start)) refuse(path, "checksum mismatch (corrupt)");
  }

  Manifest manifest;
  SessionInfo& info = manifest.info;
  info.format_version = static_cast<std::uint32_t>(version);
  std::set<std::string> seen;
  std::istringstream lines(text.substr(first_end + 1, last_start - first_end - 1));
  std::string line_text;
  int number = 1;
  while (std::getline(lines, line_text)) {
    ++number;
    const std::size_t space = line_text.find(' ');
    const std::string key = line_text.substr(0, space);
    const std::string value = space == std::string::npos ? "" : line_text.substr(space + 1);
    ManifestLine line(path, number, key, value);
    if (key != "file" && !seen.insert(key).second) line.fail("given twice");
    if (key == "created_utime") {
      info.created_utime = line.next<std::int64_t>();
    } else if (key == "created_by") {
      info.created_by = value;
      continue;
    } else if (key == "camera_width") {
      info.camera.width = line.next<int>();
    } else if (key == "camera_height") {
      info.camera.height = line.next<int>();
    } else if (key == "camera_fx") {
      info.camera.fx = line.next<double>();
    } else if (key == "camera_fy") {
      info.camera.fy = line.next<double>();
    } else if (key == "camera_cx") {
      info.camera.cx = line.next<double>();
    } else if (key == "camera_cy") {
      info.camera.cy = line.next<double>();
    } else if (key == "camera_distortion_model") {
      const std::string model = line.word();
      if (model == distortionModelName(DistortionModel::kNone)) {
        info.camera.distortion_model = DistortionModel::kNone;
      } else if (model == distortionModelName(DistortionModel::kPlumbBob)) {
        info.camera.distortion_model = DistortionModel::kPlumbBob;
      } else {
        line.fail("unknown model '" + printableExcerpt(model) + "'");
      }
    } else if (key == "camera_distortion") {
      for (double& d : info.camera.distortion) d = line.next<double>();
    } else if (key == "keyframes") {
      info.keyframes = line.next<std::int64_t>();
    } else if (key == "culled_keyframes") {
      info.culled_keyframes = line.next<std::int64_t>();
    } else if (key == "landmarks") {
      info.landmarks = line.next<std::int64_t>();
    } else if (key == "edges") {
      info.edges = line.next<std::int64_t>();
    } else if (key == "segments") {
      info.segments = line.next<std::int64_t>();
    } else if (key == "loops") {
      info.loops = line.next<std::int64_t>();
    } else if (key == "map_voxels") {
      info.map_voxels = line.next<std::int64_t>();
    } else if (key == "keyframe_min_m") {
      info.keyframe_min_m = line.vector();
    } else if (key == "keyframe_max_m") {
      info.keyframe_max_m = line.vector();
    } else if (key == "map_min_m") {
      info.map_min_m = line.vector();
    } else if (key == "map_max_m") {
      info.map_max_m = line.vector();
    } else if (key == "file") {
      ManifestFile file;
      file.name = line.word();
      if (!isPlainFileName(file.name) || file.name == kSessionManifestFile) {
        line.fail("'" + printableExcerpt(file.name) + "' is not a file of the generation");
      }
      file.size = line.next<std::uint64_t>();
      file.checksum = line.hex();
      for (const ManifestFile& other : manifest.files) {
        if (other.name == file.name) line.fail(file.name + " listed twice");
      }
      manifest.files.push_back(file);
      info.files.emplace_back(file.name, file.size);
    } else {
      // Unknown keys are skipped: a later slamd may add information without changing the format.
      continue;
    }
    line.end();
  }
  for (const char* key : {"created_utime",
                          "created_by",
                          "camera_width",
                          "camera_height",
                          "camera_fx",
                          "camera_fy",
                          "camera_cx",
                          "camera_cy",
                          "camera_distortion_model",
                          "camera_distortion",
                          "keyframes",
                          "culled_keyframes",
                          "landmarks",
                          "edges",
                          "segments",
                          "loops",
                          "map_voxels",
                          "keyframe_min_m",
                          "keyframe_max_m",
                          "map_min_m",
                          "map_max_m"}) {
    if (seen.count(key) == 0) refuse(path, std::string("no ") + key + " line");
  }
  const std::string camera = info.camera.validationError();
  if (!camera.empty()) refuse(path, "camera: " + camera);
  return manifest;
}

/// CURRENT and the manifest it leads to.
Manifest readManifest(const std::string& dir, std::string& generation_path) {
  const std::string generation = readCurrent(dir);
  generation_path = joinPath(dir, generation);
  const std::string path = joinPath(generation_path, kSessionManifestFile);
  Manifest manifest = parseManifest(path, readWhole(path, false));
  manifest.info.generation = generation;
  return manifest;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

BackendSnapshot parseBackendFiles(const std::vector<std::uint8_t>& keyframes_bin,
                                  const std::vector<std::uint8_t>& graph_bin,
                                  const std::string& label) {
  BackendSnapshot snapshot;
  parseFile(keyframes_bin, joinPath(label, kSessionKeyframesFile), [&snapshot](SessionReader& in) {
    in.header(kKeyframesMagic);
    in.setWhere("count of keyframes");
    const std::uint64_t count = in.u64();
    if (!in.fits(count, kKeyframeFixedBytes)) {
      in.setWhere("keyframe " + ofCount(in.remaining() / kKeyframeFixedBytes, count));
      in.truncated();
    }
    snapshot.keyframes.reserve(static_cast<std::size_t>(count));
    for (std::uint64_t i = 0; i < count; ++i) {
      snapshot.keyframes.push_back(readKeyframe(in, i, count));
    }
    in.expectEnd();
  });
  parseFile(graph_bin, joinPath(label, kSessionGraphFile),
            [&snapshot](SessionReader& in) { readGraph(in, snapshot); });
  const SnapshotProblem problem = snapshotProblem(snapshot);
  if (!problem.problem.empty()) refuse(joinPath(label, problem.file), problem.problem);
  return snapshot;
}

void summarizeSnapshot(const BackendSnapshot& snapshot, SessionInfo& info) {
  info.keyframes = static_cast<std::int64_t>(snapshot.keyframes.size());
  info.culled_keyframes = static_cast<std::int64_t>(snapshot.culled.size());
  info.edges = static_cast<std::int64_t>(snapshot.edges.size());
  info.loops = snapshot.num_loops;
  info.landmarks = 0;
  std::set<std::int64_t> segments;
  for (const KeyframePtr& keyframe : snapshot.keyframes) {
    if (!keyframe) continue;
    const FeatureSet& f = keyframe->features;
    for (std::size_t i = 0; i < f.size() && i < f.points.size(); ++i) {
      if (f.hasDepth(i)) ++info.landmarks;
    }
    segments.insert(keyframe->segment);
  }
  for (const KeyframeRecord& record : snapshot.records) segments.insert(record.segment);
  info.segments = static_cast<std::int64_t>(segments.size());
  info.keyframe_min_m.setZero();
  info.keyframe_max_m.setZero();
  for (std::size_t i = 0; i < snapshot.nodes.size(); ++i) {
    const Eigen::Vector3d p = snapshot.nodes[i].T_world_camera.translation();
    info.keyframe_min_m = i == 0 ? p : info.keyframe_min_m.cwiseMin(p);
    info.keyframe_max_m = i == 0 ? p : info.keyframe_max_m.cwiseMax(p);
  }
}

std::string cameraMismatch(const CameraIntrinsics& loaded, const CameraIntrinsics& current) {
  std::vector<std::string> differences;
  if (loaded.width != current.width || loaded.height != current.height) {
    differences.push_back("image size " + std::to_string(loaded.width) + "x" +
                          std::to_string(loaded.height) + " in the session, " +
                          std::to_string(current.width) + "x" + std::to_string(current.height) +
                          " now");
  }
  const std::pair<const char*, std::pair<double, double>> parameters[] = {
      {"fx", {loaded.fx, current.fx}},
      {"fy", {loaded.fy, current.fy}},
      {"cx", {loaded.cx, current.cx}},
      {"cy", {loaded.cy, current.cy}}};
  for (const auto& [name, values] : parameters) {
    // Written so that NaN counts as a difference.
    if (!(std::abs(values.first - values.second) <= kCameraTolerancePx)) {
      std::ostringstream text;
      text << name << ' ' << values.first << " px in the session, " << values.second << " px now";
      differences.push_back(text.str());
    }
  }
  if (loaded.distortion_model != current.distortion_model) {
    differences.push_back(std::string("distortion model ") +
                          distortionModelName(loaded.distortion_model) + " in the session, " +
                          distortionModelName(current.distortion_model) + " now");
  } else if (loaded.distortion_model != DistortionModel::kNone) {
    for (std::size_t i = 0; i < loaded.distortion.size(); ++i) {
      if (!(std::abs(loaded.distortion[i] - current.distortion[i]) <= 1e-9)) {
        differences.push_back("distortion coefficients differ");
        break;
      }
    }
  }
  std::string text;
  for (const std::string& difference : differences) {
    text += (text.empty() ? "" : "; ") + difference;
  }
  return text;
}

// ---------------------------------------------------------------------------------------------
// SessionWriter.

SessionWriter::SessionWriter(const std::string& dir) : dir_(dir) {
  std::error_code error;
  fs::create_directories(dir_, error);
  if (error || !fs::is_directory(dir_, error)) {
    throw SessionError("cannot save session: cannot create folder " + dir_ + ": " +
                       (error ? error.message() : std::string("not a folder")));
  }
  // CURRENT's generation is kept; any other generation folder is what a killed save left. When
  // CURRENT exists but cannot be read nothing is removed (commit() replaces everything anyway).
  std::string current;
  bool current_known = false;
  try {
    current = readCurrent(dir_);
    current_known = true;
  } catch (const SessionError&) {
    current_known = !fs::exists(joinPath(dir_, kSessionCurrentFile), error);
  }
  removeStaleTemporaryFiles({joinPath(dir_, kSessionCurrentFile)});
  std::int64_t highest = std::max<std::int64_t>(0, generationNumber(current));  // the first is 1
  std::vector<fs::path> leftovers;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir_, error)) {
    const std::string name = entry.path().filename().string();
    const std::int64_t number = generationNumber(name);
    if (number < 0) continue;
    highest = std::max(highest, number);
    if (current_known && name != current) leftovers.push_back(entry.path());
  }
  if (error) {
    throw SessionError("cannot save session: cannot list " + dir_ + ": " + error.message());
  }
  for (const fs::path& leftover : leftovers) {
    std::error_code remove_error;
    fs::remove_all(leftover, remove_error);
    if (remove_error) {
      SLAMD_LOG_WARN("session") << "cannot remove the unfinished save " << leftover.string() << ": "
                                << remove_error.message();
    } else {
      SLAMD_LOG_INFO("session") << "removed the unfinished save " << leftover.string();
    }
  }
  generation_ = generationName(highest + 1);
  generation_path_ = joinPath(dir_, generation_);
  if (!fs::create_directory(generation_path_, error) || error) {
    throw SessionError("cannot save session: cannot create folder " + generation_path_ + ": " +
                       (error ? error.message() : std::string("it exists")));
  }
}

SessionWriter::~SessionWriter() {
  if (committed_ || generation_path_.empty()) return;
  std::error_code error;  // never throws: an unfinished folder is removed by the next save
  fs::remove_all(generation_path_, error);
}

void SessionWriter::listFile(FileEntry entry) {
  for (FileEntry& existing : files_) {
    if (existing.name == entry.name) {
      existing = std::move(entry);
      return;
    }
  }
  files_.push_back(std::move(entry));
}

void SessionWriter::writeFile(const std::string& name,
                              const std::function<bool(std::ostream&)>& content) {
  const std::string path = pathFor(name);
  FileEntry entry;
  entry.name = name;
  std::string error;
  const bool written = writeFileAtomically(
      path,
      [&](std::ostream& out) {
        CountingBuffer counter(out);
        std::ostream counted(&counter);
        const bool ok = content(counted) && counted.good();
        entry.size = counter.size;
        entry.checksum = counter.checksum;
        return ok && out.good();
      },
      &error);
  if (!written) throw SessionError("cannot save session: " + error);
  listFile(std::move(entry));
}

void SessionWriter::writeBackend(const BackendSnapshot& snapshot) {
  const SnapshotProblem problem = snapshotProblem(snapshot);
  if (!problem.problem.empty()) {
    throw SessionError("cannot save session " + joinPath(generation_path_, problem.file) +
                       ": inconsistent snapshot: " + problem.problem);
  }
  writeFile(kSessionKeyframesFile, [&snapshot](std::ostream& out) {
    LittleEndianWriter w(out);
    w.raw(kKeyframesMagic, sizeof(kKeyframesMagic));
    w.u32(kSessionFormatVersion);
    w.u64(snapshot.keyframes.size());
    // One keyframe at a time: the file can be far larger than one keyframe's bytes.
    for (const KeyframePtr& keyframe : snapshot.keyframes) {
      writeKeyframe(w, *keyframe);
      if (!w.flush()) return false;
    }
    return w.flush();
  });
  const std::string graph = graphBytes(snapshot);
  writeFile(kSessionGraphFile, [&graph](std::ostream& out) {
    out.write(graph.data(), static_cast<std::streamsize>(graph.size()));
    return true;
  });
}

void SessionWriter::writeVocabulary(const Vocabulary& vocabulary) {
  writeFile(kSessionVocabularyFile, [&vocabulary](std::ostream& out) {
    vocabulary.write(out);
    return true;
  });
}

void SessionWriter::writeText(const std::string& name, const std::string& text) {
  writeFile(name, [&text](std::ostream& out) {
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    return true;
  });
}

std::string SessionWriter::pathFor(const std::string& name) const {
  if (!isPlainFileName(name) || name == kSessionManifestFile) {
    throw SessionError("cannot save session: '" + printableExcerpt(name) +
                       "' is not a file name a session can hold");
  }
  return joinPath(generation_path_, name);
}

void SessionWriter::addFile(const std::string& name) {
  FileEntry entry;
  entry.name = name;
  try {
    checksumFile(pathFor(name), entry.size, entry.checksum);
  } catch (const SessionError& e) {
    throw SessionError(std::string("cannot save session: ") + e.what());
  }
  listFile(std::move(entry));
}

void SessionWriter::commit(SessionInfo info) {
  if (committed_) throw SessionError("cannot save session: " + generation_path_ + " committed");
  for (const char* required : {kSessionKeyframesFile, kSessionGraphFile, kSessionVocabularyFile}) {
    const bool listed = std::any_of(files_.begin(), files_.end(),
                                    [required](const FileEntry& f) { return f.name == required; });
    if (!listed) {
      throw SessionError("cannot save session " + generation_path_ + ": " + required +
                         " was not written");
    }
  }
  const std::string camera = info.camera.validationError();
  if (!camera.empty()) throw SessionError("cannot save session: camera: " + camera);
  std::vector<ManifestFile> files;
  for (const FileEntry& entry : files_) files.push_back({entry.name, entry.size, entry.checksum});
  const std::string manifest = manifestText(info, files);
  std::string error;
  const auto write_text = [](const std::string& text) {
    return [&text](std::ostream& out) {
      out.write(text.data(), static_cast<std::streamsize>(text.size()));
      return true;
    };
  };
  if (!writeFileAtomically(joinPath(generation_path_, kSessionManifestFile), write_text(manifest),
                           &error)) {
    throw SessionError("cannot save session: " + error);
  }
  // Every file and its directory entry must be on disk before CURRENT names the folder.
  fsyncFolder(generation_path_);
  const std::string current = generation_ + "\n";
  if (!writeFileAtomically(joinPath(dir_, kSessionCurrentFile), write_text(current), &error)) {
    // A failure after the rename (the folder's fsync) leaves CURRENT naming this generation:
    // the folder must then stay, or CURRENT would name nothing.
    try {
      committed_ = readCurrent(dir_) == generation_;
    } catch (const SessionError&) {
      committed_ = false;
    }
    throw SessionError("cannot save session: " + error);
  }
  committed_ = true;
  // The older generations are no longer current; a failure to remove one only costs space (the
  // next save tries again).
  std::error_code list_error;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir_, list_error)) {
    const std::string name = entry.path().filename().string();
    if (generationNumber(name) < 0 || name == generation_) continue;
    std::error_code remove_error;
    fs::remove_all(entry.path(), remove_error);
    if (remove_error) {
      SLAMD_LOG_WARN("session") << "cannot remove the old save " << entry.path().string() << ": "
                                << remove_error.message();
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Reading.

SessionInfo readSessionInfo(const std::string& dir) {
  std::string generation_path;
  return readManifest(dir, generation_path).info;
}

Session loadSession(const std::string& dir) {
  Session session;
  session.dir = dir;
  const Manifest manifest = readManifest(dir, session.generation_path);
  session.info = manifest.info;
  const std::string manifest_path = joinPath(session.generation_path, kSessionManifestFile);
  auto listed = [&manifest](const std::string& name) {
    return std::any_of(manifest.files.begin(), manifest.files.end(),
                       [&name](const ManifestFile& f) { return f.name == name; });
  };
  for (const char* required : {kSessionKeyframesFile, kSessionGraphFile, kSessionVocabularyFile}) {
    if (!listed(required)) refuse(manifest_path, std::string("does not list ") + required);
  }

  // Every listed file is verified before any is parsed; the ones parsed here are read once.
  std::map<std::string, std::vector<std::uint8_t>> contents;
  for (const ManifestFile& file : manifest.files) {
    const std::string path = joinPath(session.generation_path, file.name);
    std::uint64_t size = 0;
    std::uint64_t checksum = 0;
    const bool parsed_here = file.name == kSessionKeyframesFile || file.name == kSessionGraphFile ||
                             file.name == kSessionVocabularyFile || file.name == kSessionConfigFile;
    if (parsed_here) {
      std::vector<std::uint8_t> bytes = readWhole(path, true);
      size = bytes.size();
      checksum = fnv1a64(bytes.data(), bytes.size());
      contents[file.name] = std::move(bytes);
    } else {
      checksumFile(path, size, checksum);
    }
    if (size != file.size) {
      refuse(path, std::to_string(size) + " bytes where " + kSessionManifestFile + " lists " +
                       std::to_string(file.size) + " (truncated or replaced)");
    }
    if (checksum != file.checksum) refuse(path, "checksum mismatch (corrupt)");
  }

  session.backend = parseBackendFiles(contents[kSessionKeyframesFile], contents[kSessionGraphFile],
                                      session.generation_path);
  contents.erase(kSessionKeyframesFile);  // the largest file: parsed, its bytes are not needed
  {
    const std::vector<std::uint8_t>& bytes = contents[kSessionVocabularyFile];
    std::istringstream in(std::string(bytes.begin(), bytes.end()), std::ios::binary);
    auto vocabulary = std::make_shared<Vocabulary>();
    std::string error;
    if (!vocabulary->read(in, &error)) {
      refuse(joinPath(session.generation_path, kSessionVocabularyFile), error);
    }
    session.vocabulary = std::move(vocabulary);
  }
  if (listed(kSessionMapFile))
    session.map_path = joinPath(session.generation_path, kSessionMapFile);
  if (listed(kSessionKeyframeCloudsFile)) {
    session.keyframe_clouds_path = joinPath(session.generation_path, kSessionKeyframeCloudsFile);
  }
  if (listed(kSessionConfigFile)) {
    const std::vector<std::uint8_t>& bytes = contents[kSessionConfigFile];
    session.config_yaml.assign(bytes.begin(), bytes.end());
  }
  return session;
}

}  // namespace slamd
