#include "slamd/web/viewer_model.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>

#include <Eigen/Geometry>

#include "slamd/eval/json_writer.hpp"

namespace slamd::web {
namespace {

using eval::JsonWriter;

constexpr int kProtocolVersion = 1;

std::uint64_t packKey(const octomap::OcTreeKey& key) {
  return static_cast<std::uint64_t>(key[0]) | (static_cast<std::uint64_t>(key[1]) << 16) |
         (static_cast<std::uint64_t>(key[2]) << 32);
}

void appendLittleEndian32(std::string& out, std::uint32_t value) {
  for (int byte = 0; byte < 4; ++byte)
    out.push_back(static_cast<char>((value >> (8 * byte)) & 0xff));
}

void appendLittleEndian16(std::string& out, std::uint16_t value) {
  out.push_back(static_cast<char>(value & 0xff));
  out.push_back(static_cast<char>(value >> 8));
}

std::string voxelFrameHeader(VoxelFrameKind kind, std::size_t count, double resolution_m) {
  std::string frame;
  frame.reserve(kVoxelFrameHeaderBytes + count * kVoxelRecordBytes);
  appendLittleEndian32(frame, static_cast<std::uint32_t>(kind));
  appendLittleEndian32(frame, static_cast<std::uint32_t>(count));
  const float resolution = static_cast<float>(resolution_m);
  std::uint32_t resolution_bits = 0;
  std::memcpy(&resolution_bits, &resolution, sizeof(resolution_bits));
  appendLittleEndian32(frame, resolution_bits);
  appendLittleEndian32(frame, 0);
  return frame;
}

void appendVoxelRecord(std::string& frame, std::uint64_t packed_key, bool occupied) {
  appendLittleEndian16(frame, static_cast<std::uint16_t>(packed_key & 0xffff));
  appendLittleEndian16(frame, static_cast<std::uint16_t>((packed_key >> 16) & 0xffff));
  appendLittleEndian16(frame, static_cast<std::uint16_t>((packed_key >> 32) & 0xffff));
  appendLittleEndian16(frame, occupied ? 1 : 0);
}

bool finitePose(const PoseEstimate& pose) {
  return pose.T_world_camera.matrix().allFinite() && pose.covariance.allFinite();
}

OutgoingMessage text(std::string payload) {
  return OutgoingMessage{OutgoingMessage::Kind::kText, std::move(payload)};
}

OutgoingMessage binary(std::string payload) {
  return OutgoingMessage{OutgoingMessage::Kind::kBinary, std::move(payload)};
}

/// Position (0.1 mm) and quaternion (1e-6) as JSON arrays: full double precision would triple
/// the size of a trail for nothing a viewer can show.
void appendPoseArrays(std::string& out, const SE3& T_world_camera) {
  const Eigen::Vector3d p = T_world_camera.translation();
  const Eigen::Quaterniond q(T_world_camera.rotation());
  char buffer[192];
  std::snprintf(buffer, sizeof(buffer), "\"p\":[%.4f,%.4f,%.4f],\"q\":[%.6f,%.6f,%.6f,%.6f]", p.x(),
                p.y(), p.z(), q.w(), q.x(), q.y(), q.z());
  out += buffer;
}

}  // namespace

ViewerModel::ViewerModel(Options options) : options_(std::move(options)) {}

bool ViewerModel::alive(std::int64_t now_ns) const {
  return last_message_ns_ != 0 && (now_ns - last_message_ns_) * 1e-9 < options_.alive_timeout_s;
}

void ViewerModel::restart(const char* reason) {
  // Pages clear everything on "reset"; from then on they hold nothing, so nothing pending about
  // the previous run needs sending.
  ++counters_.restarts;
  replica_ = MapReplica();
  occupied_keys_.clear();
  changed_since_broadcast_.clear();
  trail_.clear();
  trail_poses_broadcast_ = 0;
  last_pose_sequence_ = -1;
  keyframes_.reset();
  status_.reset();
  vanishing_points_.clear();
  keyframes_changed_ = status_changed_ = vanishing_changed_ = false;
  pending_resets_.emplace_back(reason);
}

void ViewerModel::onPose(const PoseEstimate& pose, std::int64_t now_ns) {
  noteAlive(now_ns);
  if (!finitePose(pose)) {
    ++counters_.poses_rejected;
    return;
  }
  // A sequence that starts again is a new slamd process (or a replayed log): a new world frame.
  if (last_pose_sequence_ >= 0 && pose.sequence < last_pose_sequence_) {
    restart("slamd restarted (the pose sequence started again)");
  }
  last_pose_sequence_ = pose.sequence;
  ++counters_.poses_received;
  const double position_variance_m2 = pose.covariance.topLeftCorner<3, 3>().trace();
  trail_.push_back(TrailPose{pose, std::sqrt(std::max(0.0, position_variance_m2))});
  if (trail_.size() > options_.max_trail_poses) {
    trail_.pop_front();
    if (trail_poses_broadcast_ > 0) --trail_poses_broadcast_;
  }
}

void ViewerModel::onKeyframes(const KeyframeTrajectory& keyframes, std::int64_t now_ns) {
  noteAlive(now_ns);
  for (const KeyframePoseEntry& keyframe : keyframes.keyframes) {
    if (!keyframe.T_world_camera.matrix().allFinite()) {
      ++malformed_;
      return;
    }
  }
  keyframes_ = keyframes;
  keyframes_changed_ = true;
}

void ViewerModel::onStatus(const slamd::status_t& status, std::int64_t now_ns) {
  noteAlive(now_ns);
  status_ = status;
  status_changed_ = true;
}

void ViewerModel::onVanishingPoint(const slamd::vanishing_point_t& point, std::int64_t now_ns) {
  noteAlive(now_ns);
  const double* d = point.direction_camera;
  if (!std::isfinite(d[0]) || !std::isfinite(d[1]) || !std::isfinite(d[2])) {
    ++malformed_;
    return;
  }
  // All vanishing points of one image share its utime; a newer image replaces them.
  if (!vanishing_points_.empty() && vanishing_points_.front().utime != point.utime) {
    vanishing_points_.clear();
  }
  vanishing_points_.push_back(point);
  vanishing_changed_ = true;
}

void ViewerModel::setOccupied(VoxelKey key, bool occupied) {
  const bool was_occupied = occupied_keys_.count(key) > 0;
  if (was_occupied == occupied) return;
  if (occupied && occupied_keys_.size() >= options_.max_voxels) return;
  changed_since_broadcast_.emplace(key, was_occupied);  // keeps the first: what pages last saw
  if (occupied) {
    occupied_keys_.insert(key);
  } else {
    occupied_keys_.erase(key);
  }
}

void ViewerModel::onMapUpdate(const MapUpdate& update, std::int64_t now_ns) {
  noteAlive(now_ns);
  // A mapper that starts its sequence again is a new slamd process (its first update is 0).
  if (update.sequence == 0 && replica_.nextSequence() > 0) {
    restart("slamd restarted (the map sequence started again)");
  }
  if (replica_.applyUpdate(update) != MapReplica::UpdateResult::kApplied) return;
  const octomap::OcTree& tree = replica_.tree();
  for (const VoxelChange& voxel : update.voxels) {
    const auto key = voxelChangeKey(voxel, tree);
    if (!key) continue;
    const octomap::OcTreeNode* node = tree.search(*key);
    setOccupied(packKey(*key), node != nullptr && tree.isNodeOccupied(node));
  }
}

bool ViewerModel::onFullMap(const FullMap& map, std::int64_t now_ns, std::string* error) {
  noteAlive(now_ns);
  if (!replica_.applyFullMap(map, error)) {
    ++counters_.full_maps_rejected;
    return false;
  }
  ++counters_.full_maps;
  resyncOccupiedFromTree();
  return true;
}

void ViewerModel::resyncOccupiedFromTree() {
  const octomap::OcTree& tree = replica_.tree();
  const unsigned max_depth = tree.getTreeDepth();
  std::unordered_set<VoxelKey> occupied_now;
  for (auto leaf = tree.begin_leafs(); leaf != tree.end_leafs(); ++leaf) {
    if (!tree.isNodeOccupied(*leaf)) continue;
    // A pruned leaf stands for a cube of finest voxels; pages show finest voxels.
    const unsigned side = 1u << (max_depth - leaf.getDepth());
    const octomap::OcTreeKey corner =
        tree.coordToKey(leaf.getX() - 0.5 * leaf.getSize() + 0.5 * tree.getResolution(),
                        leaf.getY() - 0.5 * leaf.getSize() + 0.5 * tree.getResolution(),
                        leaf.getZ() - 0.5 * leaf.getSize() + 0.5 * tree.getResolution());
    for (unsigned dz = 0; dz < side; ++dz) {
      for (unsigned dy = 0; dy < side; ++dy) {
        for (unsigned dx = 0; dx < side; ++dx) {
          if (occupied_now.size() >= options_.max_voxels) break;
          occupied_now.insert(
              packKey(octomap::OcTreeKey(corner[0] + dx, corner[1] + dy, corner[2] + dz)));
        }
      }
    }
  }
  std::vector<VoxelKey> no_longer;
  for (VoxelKey key : occupied_keys_) {
    if (!occupied_now.count(key)) no_longer.push_back(key);
  }
  for (VoxelKey key : no_longer) setOccupied(key, false);
  for (VoxelKey key : occupied_now) setOccupied(key, true);
}

bool ViewerModel::wantsFullMap(std::int64_t now_ns) {
  if (!map_requests_.due(replica_, now_ns, options_.map_request_period_s)) return false;
  ++counters_.map_requests;
  return true;
}

std::vector<OutgoingMessage> ViewerModel::takeBroadcast(std::int64_t now_ns) {
  std::vector<OutgoingMessage> messages;
  for (const std::string& reason : pending_resets_) {
    JsonWriter json;
    json.beginObject().key("type").value("reset").key("reason").value(reason).endObject();
    messages.push_back(text(json.str()));
  }
  pending_resets_.clear();
  if (trail_poses_broadcast_ < trail_.size()) {
    messages.push_back(text(
        posesMessage("poses", trail_.begin() + static_cast<std::ptrdiff_t>(trail_poses_broadcast_),
                     trail_.end())));
    trail_poses_broadcast_ = trail_.size();
  }
  if (!changed_since_broadcast_.empty()) {
    std::string frame = changedVoxelsFrame();
    changed_since_broadcast_.clear();
    if (!frame.empty()) messages.push_back(binary(std::move(frame)));
  }
  if (keyframes_changed_ && keyframes_) messages.push_back(text(keyframesMessage()));
  if (status_changed_ && status_) messages.push_back(text(statusMessage()));
  if (vanishing_changed_) messages.push_back(text(vanishingMessage()));
  keyframes_changed_ = status_changed_ = vanishing_changed_ = false;
  if ((now_ns - last_viewer_message_ns_) * 1e-9 >= 1.0) {
    messages.push_back(text(viewerMessage(now_ns)));
    last_viewer_message_ns_ = now_ns;
  }
  return messages;
}

std::vector<OutgoingMessage> ViewerModel::fullState(std::int64_t now_ns) const {
  // A page receives this between two broadcasts, so it shows what the pages that have been
  // connected all along show: only what has been broadcast (trail_poses_broadcast_, and the
  // voxels as of the last broadcast, which changed_since_broadcast_ lets us reconstruct).
  std::vector<OutgoingMessage> messages;
  messages.push_back(text(helloMessage()));
  messages.push_back(binary(replaceVoxelsFrame()));
  messages.push_back(
      text(posesMessage("trail", trail_.begin(),
                        trail_.begin() + static_cast<std::ptrdiff_t>(trail_poses_broadcast_))));
  if (keyframes_ && !keyframes_changed_) messages.push_back(text(keyframesMessage()));
  if (status_ && !status_changed_) messages.push_back(text(statusMessage()));
  if (!vanishing_points_.empty() && !vanishing_changed_) {
    messages.push_back(text(vanishingMessage()));
  }
  messages.push_back(text(viewerMessage(now_ns)));
  return messages;
}

std::string ViewerModel::helloMessage() const {
  JsonWriter json;
  json.beginObject()
      .key("type")
      .value("hello")
      .key("protocol")
      .value(kProtocolVersion)
      .key("frame_id")
      .value(trail_.empty() ? std::string("world") : trail_.back().pose.parent_frame)
      .key("resolution_m")
      .value(replica_.tree().getResolution())
      .key("up_axis")
      .value(options_.up_axis)
      .endObject();
  return json.str();
}

std::string ViewerModel::posesMessage(const char* type, std::deque<TrailPose>::const_iterator begin,
                                      std::deque<TrailPose>::const_iterator end) const {
  std::string out = std::string("{\"type\":\"") + type + "\",\"poses\":[";
  out.reserve(out.size() + static_cast<std::size_t>(end - begin) * 160);
  for (auto it = begin; it != end; ++it) {
    if (it != begin) out += ',';
    char head[128];
    std::snprintf(head, sizeof(head), "{\"utime\":%lld,\"seq\":%lld,",
                  static_cast<long long>(it->pose.utime),
                  static_cast<long long>(it->pose.sequence));
    out += head;
    appendPoseArrays(out, it->pose.T_world_camera);
    char tail[160];
    std::snprintf(
        tail, sizeof(tail), ",\"state\":%d,\"state_name\":\"%s\",\"source\":%d,\"sigma_m\":%s}",
        static_cast<int>(it->pose.tracking_state), trackingStateName(it->pose.tracking_state),
        static_cast<int>(it->pose.source), JsonWriter::number(it->sigma_m).c_str());
    out += tail;
  }
  out += "]}";
  return out;
}

std::string ViewerModel::keyframesMessage() const {
  char head[256];
  std::snprintf(head, sizeof(head),
                "{\"type\":\"keyframes\",\"sequence\":%lld,\"num_loops\":%d,"
                "\"num_relocalizations\":%d,\"optimization_ms\":%s,\"keyframes\":[",
                static_cast<long long>(keyframes_->sequence), keyframes_->num_loops,
                keyframes_->num_relocalizations,
                JsonWriter::number(keyframes_->optimization_ms).c_str());
  std::string out = head;
  for (std::size_t i = 0; i < keyframes_->keyframes.size(); ++i) {
    const KeyframePoseEntry& keyframe = keyframes_->keyframes[i];
    char entry[96];
    std::snprintf(entry, sizeof(entry), "%s{\"id\":%lld,\"utime\":%lld,", i == 0 ? "" : ",",
                  static_cast<long long>(keyframe.keyframe_id),
                  static_cast<long long>(keyframe.utime));
    out += entry;
    appendPoseArrays(out, keyframe.T_world_camera);
    out += '}';
  }
  out += "]}";
  return out;
}

std::string ViewerModel::statusMessage() const {
  const slamd::status_t& status = *status_;
  JsonWriter json;
  json.beginObject().key("type").value("status").key("utime").value(status.utime);
  json.key("stages").beginArray();
  for (const slamd::stage_status_t& stage : status.stages) {
    json.beginObject()
        .key("name")
        .value(stage.name)
        .key("rate_hz")
        .value(stage.rate_hz)
        .key("latency_p50_ms")
        .value(stage.latency_p50_ms)
        .key("latency_p95_ms")
        .value(stage.latency_p95_ms)
        .key("latency_p99_ms")
        .value(stage.latency_p99_ms)
        .key("queue_depth")
        .value(stage.queue_depth)
        .key("queue_capacity")
        .value(stage.queue_capacity)
        .key("drops")
        .value(stage.drops)
        .key("errors")
        .value(stage.errors)
        .key("processed")
        .value(stage.processed)
        .endObject();
  }
  json.endArray()
      .key("end_to_end_p50_ms")
      .value(status.end_to_end_p50_ms)
      .key("end_to_end_p95_ms")
      .value(status.end_to_end_p95_ms)
      .key("end_to_end_p99_ms")
      .value(status.end_to_end_p99_ms)
      .key("tracking_state")
      .value(static_cast<int>(status.tracking_state))
      .key("tracking_state_name")
      .value(trackingStateName(static_cast<TrackingState>(status.tracking_state)))
      .key("map_occupied_voxels")
      .value(status.map_occupied_voxels)
      .key("map_total_voxels")
      .value(status.map_total_voxels)
      .key("num_keyframes")
      .value(status.num_keyframes)
      .key("num_loops")
      .value(status.num_loops)
      .key("num_relocalizations")
      .value(status.num_relocalizations)
      .key("memory_rss_mb")
      .value(status.memory_rss_mb)
      .key("memory_limit_mb")
      .value(status.memory_limit_mb)
      .key("memory_pressure")
      .value(static_cast<int>(status.memory_pressure))
      .key("message")
      .value(status.message)
      // slamd has no corridor mode yet (issue 23); the page shows that plainly.
      .key("corridor_mode")
      .value("not reported by slamd")
      .endObject();
  return json.str();
}

std::string ViewerModel::vanishingMessage() const {
  JsonWriter json;
  json.beginObject().key("type").value("vp").key("utime").value(
      vanishing_points_.empty() ? std::int64_t{0} : vanishing_points_.front().utime);
  json.key("directions").beginArray();
  for (const slamd::vanishing_point_t& point : vanishing_points_) {
    json.beginObject().key("direction_camera").beginArray();
    for (double component : point.direction_camera) json.value(component);
    json.endArray()
        .key("accepted")
        .value(static_cast<bool>(point.accepted))
        .key("landmark_id")
        .value(point.landmark_id)
        .key("num_supporting_lines")
        .value(point.num_supporting_lines)
        .endObject();
  }
  json.endArray().endObject();
  return json.str();
}

std::string ViewerModel::viewerMessage(std::int64_t now_ns) const {
  JsonWriter json;
  json.beginObject()
      .key("type")
      .value("viewer")
      .key("poses_received")
      .value(counters_.poses_received)
      .key("voxels")
      .value(occupied_keys_.size())
      .key("map_synchronised")
      .value(replica_.synchronised())
      .key("full_maps")
      .value(counters_.full_maps)
      .key("updates_applied")
      .value(replica_.updatesApplied())
      .key("gaps")
      .value(replica_.gaps())
      .key("map_requests")
      .value(counters_.map_requests)
      .key("malformed")
      .value(malformed_ + counters_.poses_rejected + counters_.full_maps_rejected +
             replica_.rejected())
      .key("restarts")
      .value(counters_.restarts)
      .key("slamd_alive")
      .value(alive(now_ns))
      .key("clients")
      .value(clients_)
      .endObject();
  return json.str();
}

std::string ViewerModel::replaceVoxelsFrame() const {
  // The voxels as pages last saw them: the current set with the changes since the last broadcast
  // undone.
  // Counted from the changes alone, so the whole set is walked once.
  std::size_t count = occupied_keys_.size();
  for (const auto& [key, was_occupied] : changed_since_broadcast_) {
    count -= occupied_keys_.count(key);
    count += was_occupied ? 1 : 0;
  }
  std::string frame =
      voxelFrameHeader(VoxelFrameKind::kReplace, count, replica_.tree().getResolution());
  for (VoxelKey key : occupied_keys_) {
    if (!changed_since_broadcast_.count(key)) appendVoxelRecord(frame, key, true);
  }
  for (const auto& [key, was_occupied] : changed_since_broadcast_) {
    if (was_occupied) appendVoxelRecord(frame, key, true);
  }
  return frame;
}

std::string ViewerModel::changedVoxelsFrame() const {
  std::size_t count = 0;
  for (const auto& [key, was_occupied] : changed_since_broadcast_) {
    if (occupied_keys_.count(key) != static_cast<std::size_t>(was_occupied)) ++count;
  }
  if (count == 0) return {};
  std::string frame =
      voxelFrameHeader(VoxelFrameKind::kChanges, count, replica_.tree().getResolution());
  for (const auto& [key, was_occupied] : changed_since_broadcast_) {
    const bool occupied = occupied_keys_.count(key) > 0;
    if (occupied != was_occupied) appendVoxelRecord(frame, key, occupied);
  }
  return frame;
}

}  // namespace slamd::web
