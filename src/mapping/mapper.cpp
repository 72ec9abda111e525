#include "slamd/mapping/mapper.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <type_traits>

#include <octomap/AbstractOcTree.h>

#include "slamd/common/file_io.hpp"
#include "slamd/mapping/octree_stream.hpp"

namespace slamd {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// Empty when T is a finite rigid transform, otherwise why not.
std::string poseError(const SE3& T) {
  if (!T.matrix().allFinite()) return "pose is not finite";
  const Eigen::Matrix3d R = T.linear();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-3 || R.determinant() < 0.0) {
    return "pose rotation is not orthonormal";
  }
  if (!(T.matrix().row(3) - Eigen::RowVector4d(0, 0, 0, 1)).isZero(1e-9)) {
    return "pose is not a rigid transform";
  }
  return {};
}

/// Heap bytes of a kept cloud's points and colours, as keyframe_cloud_bytes counts them.
std::int64_t cloudBytes(const PointCloud& cloud) {
  return static_cast<std::int64_t>(cloud.points.size() * sizeof(Eigen::Vector3f) +
                                   cloud.colors_bgr.size() * sizeof(ColorBgr));
}

/// How many parts of `part_points` (> 0) a cloud of `points` is cut into (at least one).
std::size_t partsOf(std::size_t points, std::size_t part_points) {
  // Not (points + part_points - 1) / part_points: a restored part_points may be near the limit.
  return std::max<std::size_t>(1, points / part_points + (points % part_points != 0 ? 1 : 0));
}

/// Farther from the camera than any sensor measures (metres): a restored point beyond it is
/// refused, which keeps the float arithmetic of its ray finite.
constexpr float kMaxRecordPointM = 1e6f;

/// Queue priority of steps done before any move (see Mapper::keyframes_queued_).
constexpr double kFirst = std::numeric_limits<double>::infinity();

/// A voxel's log-odds closer to zero than this after a contribution was taken out: nothing else
/// saw it (sums of hits and misses are otherwise at least about 0.03 from zero).
constexpr float kEmptyLogOdds = 1e-4f;

/// Deletes the finest voxel at `key` and every ancestor left without children (the voxel is
/// unknown again). OcTree::deleteNode cannot be used: it deletes an emptied parent whose child
/// array is still allocated (an assertion, or a leak without assertions). Here such a parent is
/// expanded and pruned first, which frees the array, through OctoMap's public node API.
template <typename Tree>
void deleteVoxel(Tree& tree, const octomap::OcTreeKey& key) {
  using Node = typename Tree::NodeType;
  const unsigned depth_max = tree.getTreeDepth();
  std::vector<Node*> path;      // path[d]: the node at depth d
  std::vector<unsigned> child;  // child[d]: which child of path[d] leads to the voxel
  Node* node = tree.getRoot();
  if (node == nullptr) return;
  for (unsigned depth = 0; depth < depth_max; ++depth) {
    const unsigned pos = octomap::computeChildIdx(key, static_cast<int>(depth_max - 1 - depth));
    if (!tree.nodeChildExists(node, pos)) return;  // not there (a pruned block is not deleted)
    path.push_back(node);
    child.push_back(pos);
    node = tree.getNodeChild(node, pos);
  }
  for (std::size_t d = path.size(); d-- > 0;) {
    tree.deleteNodeChild(path[d], child[d]);
    if (tree.nodeHasChildren(path[d])) return;
    if (d == 0) {
      tree.clear();  // the last voxel of the map
      return;
    }
    // path[d] is now childless but still holds its (empty) child array: free it.
    tree.expandNode(path[d]);
    tree.pruneNode(path[d]);
  }
}

/// Mapper::coarsenFarMap() on one tree: a depth-first walk that merges far blocks bottom-up, so
/// that blocks merged at one level can merge again at the next.
template <typename Tree>
class FarMapCoarsener {
 public:
  using Node = typename Tree::NodeType;

  FarMapCoarsener(Tree& tree, const Eigen::Vector3d& near_point_m, double near_radius_m, int levels,
                  std::vector<Eigen::AlignedBox3d> kept_boxes)
      : tree_(tree),
        near_point_m_(near_point_m),
        near_radius_m_(near_radius_m),
        depth_max_(tree.getTreeDepth()),
        first_merging_depth_(depth_max_ - static_cast<unsigned>(levels)),
        kept_boxes_(std::move(kept_boxes)) {}

  CoarsenResult run() {
    Node* root = tree_.getRoot();
    if (root == nullptr || first_merging_depth_ >= depth_max_) return result_;
    const std::size_t nodes_before = tree_.size();
    const octomap::key_type root_key_value = octomap::key_type{1} << (depth_max_ - 1);
    visit(root, 0, octomap::OcTreeKey(root_key_value, root_key_value, root_key_value));
    result_.nodes_removed = nodes_before - tree_.size();
    return result_;
  }

 private:
  void visit(Node* node, unsigned depth, const octomap::OcTreeKey& key) {
    const double half_m = 0.5 * tree_.getNodeSize(depth);
    const octomap::point3d c = tree_.keyToCoord(key, depth);
    const Eigen::Vector3d centre(c.x(), c.y(), c.z());
    const Eigen::Vector3d half = Eigen::Vector3d::Constant(half_m);
    const Eigen::AlignedBox3d cube(centre - half, centre + half);
    // Nothing in a cube wholly within the radius is far.
    if (((centre - near_point_m_).cwiseAbs() + half).norm() <= near_radius_m_) return;
    // Children below the finest level's parents have children of their own to visit.
    for (unsigned i = 0; depth + 1 < depth_max_ && i < 8; ++i) {
      if (!tree_.nodeChildExists(node, i)) continue;
      Node* child = tree_.getNodeChild(node, i);
      if (!tree_.nodeHasChildren(child)) continue;
      const octomap::key_type child_offset = octomap::key_type{1} << (depth_max_ - 2 - depth);
      octomap::OcTreeKey child_key;
      octomap::computeChildKey(i, child_offset, key, child_key);
      visit(child, depth + 1, child_key);
    }
    if (depth < first_merging_depth_ || cube.exteriorDistance(near_point_m_) <= near_radius_m_) {
      return;
    }
    for (const Eigen::AlignedBox3d& box : kept_boxes_) {
      if (box.intersects(cube)) return;
    }
    merge(node);
  }

  /// Merges the children of `node` (all leaves) into it, when the rule allows.
  void merge(Node* node) {
    int known = 0;
    bool any_occupied = false;
    float max_log_odds = -std::numeric_limits<float>::infinity();
    int coloured = 0;
    int colour_sum[3] = {0, 0, 0};
    for (unsigned i = 0; i < 8; ++i) {
      if (!tree_.nodeChildExists(node, i)) continue;
      const Node* child = tree_.getNodeChild(node, i);
      if (tree_.nodeHasChildren(child)) return;  // a finer part that did not merge stays fine
      ++known;
      max_log_odds = std::max(max_log_odds, child->getLogOdds());
      const bool occupied = tree_.isNodeOccupied(child);
      any_occupied = any_occupied || occupied;
      if constexpr (std::is_same_v<Node, octomap::ColorOcTreeNode>) {
        if (occupied && child->isColorSet()) {
          const octomap::ColorOcTreeNode::Color colour = child->getColor();
          colour_sum[0] += colour.r;
          colour_sum[1] += colour.g;
          colour_sum[2] += colour.b;
          ++coloured;
        }
      }
    }
    // Free space is merged only where it was all seen: unknown never becomes free.
    if (known == 0 || (!any_occupied && known < 8)) return;
    for (unsigned i = 0; i < 8; ++i) {
      Node* child = tree_.nodeChildExists(node, i) ? tree_.getNodeChild(node, i)
                                                   : tree_.createNodeChild(node, i);
      child->setLogOdds(max_log_odds);
      if constexpr (std::is_same_v<Node, octomap::ColorOcTreeNode>) {
        if (coloured > 0) {
          child->setColor(static_cast<std::uint8_t>(colour_sum[0] / coloured),
                          static_cast<std::uint8_t>(colour_sum[1] / coloured),
                          static_cast<std::uint8_t>(colour_sum[2] / coloured));
        } else {
          child->setColor(255, 255, 255);  // OctoMap's "no colour"
        }
      }
    }
    // The children are now equal leaves: pruning frees them and their array.
    if (tree_.pruneNode(node)) ++result_.blocks_merged;
  }

  Tree& tree_;
  Eigen::Vector3d near_point_m_;
  double near_radius_m_;
  unsigned depth_max_;
  unsigned first_merging_depth_;
  std::vector<Eigen::AlignedBox3d> kept_boxes_;
  CoarsenResult result_;
};

/// The box (map frame) that a cloud's rays from the camera reach at T_world_camera, rays cut at
/// max_range_m as they go in, grown by margin_m.
Eigen::AlignedBox3d reachOf(const PointCloud& cloud_camera, const SE3& T_world_camera,
                            double max_range_m, double margin_m) {
  Eigen::AlignedBox3d box(T_world_camera.translation());
  for (const Eigen::Vector3f& p : cloud_camera.points) {
    const Eigen::Vector3d ray = p.cast<double>();
    const double range_m = ray.norm();
    box.extend(T_world_camera * (range_m > max_range_m ? ray * (max_range_m / range_m) : ray));
  }
  const Eigen::Vector3d margin = Eigen::Vector3d::Constant(margin_m);
  return Eigen::AlignedBox3d(box.min() - margin, box.max() + margin);
}

std::string extensionOf(const std::string& path) {
  return std::filesystem::path(path).extension().string();
}

/// Per-frame voxel de-duplication in a dense bit mask over the frame's key bounding box.
class DenseKeyMask {
 public:
  /// False when the box is too large for a mask (the caller falls back to a hash set).
  bool reset(const octomap::OcTreeKey& min_key, const octomap::OcTreeKey& max_key) {
    std::uint64_t cells = 1;
    for (unsigned i = 0; i < 3; ++i) {
      min_[i] = min_key[i];
      dims_[i] = static_cast<std::uint64_t>(max_key[i] - min_key[i]) + 1;
      cells *= dims_[i];
    }
    // 2^28 bits = 32 MiB: larger boxes (fine resolutions with long ranges) use the hash set.
    if (cells > (std::uint64_t{1} << 28)) return false;
    words_.assign((cells + 63) / 64, 0);
    return true;
  }

  /// True the first time a key is marked in this frame.
  bool mark(const octomap::OcTreeKey& key) {
    const std::uint64_t x = static_cast<std::uint64_t>(key[0]) - min_[0];
    const std::uint64_t y = static_cast<std::uint64_t>(key[1]) - min_[1];
    const std::uint64_t z = static_cast<std::uint64_t>(key[2]) - min_[2];
    // Unsigned wrap-around turns keys below the box into huge values, caught here too.
    if (x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return false;
    const std::uint64_t index = (z * dims_[1] + y) * dims_[0] + x;
    std::uint64_t& word = words_[index >> 6];
    const std::uint64_t bit = std::uint64_t{1} << (index & 63);
    if (word & bit) return false;
    word |= bit;
    return true;
  }

 private:
  std::uint64_t min_[3] = {0, 0, 0};
  std::uint64_t dims_[3] = {1, 1, 1};
  std::vector<std::uint64_t> words_;
};

}  // namespace

struct Mapper::Scratch {
  std::vector<Eigen::Vector3f> points_world;
  std::vector<octomap::point3d> ends;
  std::vector<octomap::OcTreeKey> end_keys;
  std::vector<std::uint8_t> end_occupied;
  std::vector<std::uint32_t> end_source;  ///< index of the point each end came from
  std::vector<octomap::OcTreeKey> free_keys;
  std::vector<octomap::OcTreeKey> occupied_keys;
  DenseKeyMask mask;
  octomap::KeySet key_set;
  octomap::KeyRay ray;
  octomap::Pointcloud octomap_cloud;
};

const char* toString(IntegrationStatus status) {
  switch (status) {
    case IntegrationStatus::kOk:
      return "ok";
    case IntegrationStatus::kBadFrame:
      return "bad frame";
    case IntegrationStatus::kBadPose:
      return "bad pose";
    case IntegrationStatus::kNoPoints:
      return "no valid points";
  }
  return "unknown";
}

Eigen::Matrix3d gridAxes(UpAxis up_axis) {
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  const Eigen::Vector3d y = Eigen::Vector3d::UnitY();
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d u;
  Eigen::Vector3d up;
  switch (up_axis) {
    case UpAxis::kPlusX:
      u = y, up = x;
      break;
    case UpAxis::kMinusX:
      u = z, up = -x;
      break;
    case UpAxis::kPlusY:
      u = x, up = y;
      break;
    case UpAxis::kPlusZ:
      u = x, up = z;
      break;
    case UpAxis::kMinusZ:
      u = x, up = -z;
      break;
    case UpAxis::kMinusY:
    default:
      u = x, up = -y;
      break;
  }
  Eigen::Matrix3d R;
  R.row(0) = u.transpose();
  R.row(1) = up.cross(u).transpose();  // v = up x u makes (u, v, up) right-handed
  R.row(2) = up.transpose();
  return R;
}

std::uint8_t OccupancyGrid2D::at(double u_m, double v_m) const {
  if (cells.empty() || !(resolution_m > 0.0)) return kUnknown;
  const double ix = std::floor((u_m - origin_u_m) / resolution_m);
  const double iy = std::floor((v_m - origin_v_m) / resolution_m);
  if (!(ix >= 0 && iy >= 0 && ix < cells.cols && iy < cells.rows)) return kUnknown;
  return cells.at<std::uint8_t>(static_cast<int>(iy), static_cast<int>(ix));
}

template <typename Function>
decltype(auto) Mapper::withTree(Function&& function) {
  if (color_tree_) return function(*color_tree_);
  return function(*tree_);
}

template <typename Function>
decltype(auto) Mapper::withTree(Function&& function) const {
  if (color_tree_) return function(static_cast<const octomap::ColorOcTree&>(*color_tree_));
  return function(static_cast<const octomap::OcTree&>(*tree_));
}

Mapper::Mapper(const MappingConfig& config) : config_(config), scratch_(new Scratch) {
  if (const std::string error = config_.validationError(); !error.empty()) {
    throw std::invalid_argument(error);
  }
  makeEmptyTree(config_.resolution_m, config_.color);
  configureTree();
  if (!config_.load_path.empty()) {
    const MapFileResult loaded = loadMap(config_.load_path);
    if (!loaded.ok) throw std::runtime_error(loaded.error);
  }
}

Mapper::~Mapper() = default;

void Mapper::makeEmptyTree(double resolution_m, bool color) {
  tree_.reset();
  color_tree_.reset();
  if (color) {
    color_tree_ = std::make_unique<octomap::ColorOcTree>(resolution_m);
  } else {
    tree_ = std::make_unique<octomap::OcTree>(resolution_m);
  }
  inner_dirty_ = false;
}

void Mapper::configureTree() {
  withTree([this](auto& tree) {
    tree.setProbHit(config_.prob_hit);
    tree.setProbMiss(config_.prob_miss);
    if (config_.keep_keyframe_clouds) {
      // Probabilities 0 and 1 are log-odds of -inf and +inf: no clamping, so that a keyframe's
      // contribution can be taken out exactly (see the header).
      tree.setClampingThresMin(0.0);
      tree.setClampingThresMax(1.0);
    } else {
      tree.setClampingThresMin(config_.clamp_min);
      tree.setClampingThresMax(config_.clamp_max);
    }
    tree.setOccupancyThres(config_.occupancy_threshold);
    tree.enableChangeDetection(true);
    tree.resetChangeDetection();
  });
}

double Mapper::resolution() const {
  return withTree([](const auto& tree) { return tree.getResolution(); });
}

void Mapper::ensureInnerOccupancy() {
  // Frames are inserted with OctoMap's lazy evaluation (inner nodes untouched, much faster); the
  // inner nodes are refreshed only when something reads them.
  if (!inner_dirty_) return;
  withTree([](auto& tree) { tree.updateInnerOccupancy(); });
  inner_dirty_ = false;
}

const octomap::OcTree* Mapper::ocTree() {
  ensureInnerOccupancy();
  return tree_.get();
}

const octomap::ColorOcTree* Mapper::colorOcTree() {
  ensureInnerOccupancy();
  return color_tree_.get();
}

std::size_t Mapper::numLeafNodes() const {
  return withTree([](const auto& tree) { return tree.getNumLeafNodes(); });
}

VoxelCounts Mapper::countVoxels() const {
  return withTree([](const auto& tree) {
    VoxelCounts counts;
    for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
      ++counts.leaves;
      if (tree.isNodeOccupied(*it)) ++counts.occupied;
    }
    return counts;
  });
}

std::size_t Mapper::memoryBytes() const {
  return withTree([](const auto& tree) { return tree.memoryUsage(); });
}

int Mapper::occupancyAt(const Eigen::Vector3d& point_m) const {
  if (!point_m.allFinite()) return -1;
  return withTree([&point_m](const auto& tree) {
    octomap::OcTreeKey key;
    if (!tree.coordToKeyChecked(point_m.x(), point_m.y(), point_m.z(), key)) return -1;
    const auto* node = tree.search(key);
    if (node == nullptr) return -1;
    return tree.isNodeOccupied(node) ? 1 : 0;
  });
}

// --- integration -------------------------------------------------------------------------------

bool Mapper::rejectBadPose(const SE3& T_world_camera, IntegrationResult& result) {
  const std::string error = poseError(T_world_camera);
  if (error.empty()) return false;
  result.status = IntegrationStatus::kBadPose;
  result.error = error;
  ++stats_.frames_bad_pose;
  return true;
}

IntegrationResult Mapper::integrate(const RgbdFrame& frame, const SE3& T_world_camera,
                                    std::optional<std::int64_t> keyframe_id) {
  return integrateFrame(frame, T_world_camera, keyframe_id, KeyframeInsertion::kNow);
}

IntegrationResult Mapper::addKeyframe(const RgbdFrame& frame, const SE3& T_world_camera,
                                      std::int64_t keyframe_id) {
  return integrateFrame(frame, T_world_camera, keyframe_id, KeyframeInsertion::kQueued);
}

IntegrationResult Mapper::holdKeyframe(const RgbdFrame& frame, const SE3& T_world_camera,
                                       std::int64_t keyframe_id) {
  return integrateFrame(frame, T_world_camera, keyframe_id, KeyframeInsertion::kQueuedOrDropped);
}

IntegrationResult Mapper::integrateFrame(const RgbdFrame& frame, const SE3& T_world_camera,
                                         std::optional<std::int64_t> keyframe_id,
                                         KeyframeInsertion insertion) {
  IntegrationResult result;
  if (rejectBadPose(T_world_camera, result)) return result;
  const auto t_cloud = Clock::now();
  DepthToCloudOptions options;
  options.min_depth_m = config_.min_depth_m;
  options.max_depth_m = config_.max_depth_m;
  options.pixel_stride = config_.pixel_stride;
  const DepthCloudStatus cloud_status =
      depthToCloud(frame.depth_m, frame.color_bgr, frame.intrinsics, options, cloud_, result.depth);
  result.cloud_ms = msSince(t_cloud);
  if (cloud_status != DepthCloudStatus::kOk) {
    result.status = IntegrationStatus::kBadFrame;
    result.error = toString(cloud_status);
    ++stats_.frames_bad_frame;
    return result;
  }
  stats_.depth_nan += result.depth.nan;
  stats_.depth_infinite += result.depth.infinite;
  stats_.depth_zero += result.depth.zero;
  stats_.depth_negative += result.depth.negative;
  stats_.depth_out_of_range += result.depth.too_near + result.depth.too_far;

  const auto t_filter = Clock::now();
  voxel_filter_.apply(cloud_, config_.voxel_filter_m, config_.voxel_filter_mode, filtered_);
  result.filter_ms = msSince(t_filter);
  result.points_filtered = filtered_.size();
  latest_utime_ = std::max(latest_utime_, frame.utime);
  return insertFiltered(std::move(result), T_world_camera, keyframe_id, frame.utime, insertion);
}

IntegrationResult Mapper::integrateCloud(const PointCloud& cloud_camera, const SE3& T_world_camera,
                                         Utime utime, std::optional<std::int64_t> keyframe_id) {
  IntegrationResult result;
  if (rejectBadPose(T_world_camera, result)) return result;
  // Drop non-finite points here so that nothing below ever sees them.
  filtered_.clear();
  const bool with_color = cloud_camera.colors_bgr.size() == cloud_camera.points.size();
  for (std::size_t i = 0; i < cloud_camera.points.size(); ++i) {
    if (!cloud_camera.points[i].allFinite()) {
      ++result.depth.nan;
      continue;
    }
    filtered_.points.push_back(cloud_camera.points[i]);
    if (with_color && cloud_camera.hasColor())
      filtered_.colors_bgr.push_back(cloud_camera.colors_bgr[i]);
  }
  stats_.depth_nan += result.depth.nan;
  result.depth.valid = static_cast<std::int64_t>(filtered_.size());
  result.points_filtered = filtered_.size();
  latest_utime_ = std::max(latest_utime_, utime);
  return insertFiltered(std::move(result), T_world_camera, keyframe_id, utime,
                        KeyframeInsertion::kNow);
}

IntegrationResult Mapper::insertFiltered(IntegrationResult result, const SE3& T_world_camera,
                                         std::optional<std::int64_t> keyframe_id, Utime utime,
                                         KeyframeInsertion insertion) {
  if (!keyframe_id) return insertCameraCloud(filtered_, T_world_camera, std::move(result));
  forgetKeyframe(*keyframe_id);  // an id integrated again replaces the old one
  if (rejectUninsertable(filtered_, T_world_camera, result)) return result;
  if (!keepKeyframe(*keyframe_id, filtered_, T_world_camera, utime)) {
    if (insertion == KeyframeInsertion::kQueuedOrDropped) return result;     // not in the map frame
    return insertCameraCloud(filtered_, T_world_camera, std::move(result));  // cannot move
  }
  result.keyframe_cloud_kept = true;
  ++stats_.frames_integrated;
  stats_.points_inserted += static_cast<std::int64_t>(filtered_.size());
  if (insertion != KeyframeInsertion::kNow) {
    queueKeyframe(kFirst, *keyframe_id);
    return result;
  }
  const auto t_insert = Clock::now();
  KeyframeCloud& keyframe = keyframes_.at(*keyframe_id);
  while (keyframe.parts_in_map < keyframe.parts) {
    putPart(keyframe, keyframe.parts_in_map, Contribution::kPutIn);
    ++keyframe.parts_in_map;
  }
  result.insert_ms = msSince(t_insert);
  return result;
}

bool Mapper::originOnMap(const SE3& T_world_camera) const {
  const Eigen::Vector3d t = T_world_camera.translation();
  const octomap::point3d origin(static_cast<float>(t.x()), static_cast<float>(t.y()),
                                static_cast<float>(t.z()));
  return withTree([&origin](const auto& tree) {
    octomap::OcTreeKey key;
    return tree.coordToKeyChecked(origin, key);
  });
}

bool Mapper::rejectUninsertable(const PointCloud& cloud_camera, const SE3& T_world_camera,
                                IntegrationResult& result) {
  if (!originOnMap(T_world_camera)) {
    result.status = IntegrationStatus::kBadPose;
    result.error = "sensor origin lies outside the map's extent";
    ++stats_.frames_bad_pose;
    return true;
  }
  if (cloud_camera.empty()) {
    result.status = IntegrationStatus::kNoPoints;
    result.error = "no valid depth in the frame";
    ++stats_.frames_no_points;
    return true;
  }
  return false;
}

IntegrationResult Mapper::insertCameraCloud(const PointCloud& cloud_camera,
                                            const SE3& T_world_camera, IntegrationResult result,
                                            Contribution contribution) {
  const auto t_insert = Clock::now();
  if (rejectUninsertable(cloud_camera, T_world_camera, result)) return result;
  const Eigen::Vector3d t = T_world_camera.translation();
  const octomap::point3d origin(static_cast<float>(t.x()), static_cast<float>(t.y()),
                                static_cast<float>(t.z()));
  const Eigen::Matrix3f R = T_world_camera.linear().cast<float>();
  const Eigen::Vector3f t_f = t.cast<float>();
  std::vector<Eigen::Vector3f>& world = scratch_->points_world;
  world.resize(cloud_camera.size());
  for (std::size_t i = 0; i < cloud_camera.size(); ++i) world[i] = R * cloud_camera.points[i] + t_f;
  withTree([&](auto& tree) { insertIntoTree(tree, origin, cloud_camera, contribution, result); });
  inner_dirty_ = true;
  stats_.points_off_map += static_cast<std::int64_t>(result.points_off_map);
  stats_.points_inserted += static_cast<std::int64_t>(cloud_camera.size() - result.points_off_map);
  ++stats_.frames_integrated;
  if (config_.prune_every_frames > 0 && ++frames_since_prune_ >= config_.prune_every_frames) {
    frames_since_prune_ = 0;
    withTree([](auto& tree) { tree.prune(); });
  }
  result.insert_ms = msSince(t_insert);
  return result;
}

template <typename Tree>
void Mapper::insertIntoTree(Tree& tree, const octomap::point3d& origin,
                            const PointCloud& cloud_camera, Contribution contribution,
                            IntegrationResult& result) {
  const auto start = Clock::now();
  Scratch& s = *scratch_;
  // s.points_world holds cloud_camera moved into the map frame (insertCameraCloud).
  s.ends.clear();
  s.end_keys.clear();
  s.end_occupied.clear();
  s.end_source.clear();
  s.free_keys.clear();
  s.occupied_keys.clear();

  const float max_range = static_cast<float>(config_.max_range_m);
  octomap::OcTreeKey origin_key;
  tree.coordToKeyChecked(origin, origin_key);
  octomap::OcTreeKey min_key = origin_key;
  octomap::OcTreeKey max_key = origin_key;
  for (std::size_t i = 0; i < s.points_world.size(); ++i) {
    const Eigen::Vector3f& p = s.points_world[i];
    const octomap::point3d point(p.x(), p.y(), p.z());
    const octomap::point3d delta = point - origin;
    const float range = static_cast<float>(delta.norm());
    const bool occupied = range <= max_range;
    // Rays beyond the maximum range only clear space up to it (OctoMap's convention).
    const octomap::point3d end = occupied ? point : origin + delta * (max_range / range);
    octomap::OcTreeKey key;
    if (!tree.coordToKeyChecked(end, key)) {
      ++result.points_off_map;
      continue;
    }
    s.ends.push_back(end);
    s.end_keys.push_back(key);
    s.end_occupied.push_back(occupied ? 1 : 0);
    s.end_source.push_back(static_cast<std::uint32_t>(i));
    for (unsigned k = 0; k < 3; ++k) {
      min_key[k] = std::min(min_key[k], key[k]);
      max_key[k] = std::max(max_key[k], key[k]);
    }
  }

  if (config_.insertion == InsertionMethod::kDenseMask) {
    const bool dense = s.mask.reset(min_key, max_key);
    s.key_set.clear();
    const auto mark = [&s, dense](const octomap::OcTreeKey& key) {
      return dense ? s.mask.mark(key) : s.key_set.insert(key).second;
    };
    // Endpoints first: a voxel hit by one ray and crossed by another counts as occupied.
    for (std::size_t i = 0; i < s.end_keys.size(); ++i) {
      if (s.end_occupied[i] && mark(s.end_keys[i])) s.occupied_keys.push_back(s.end_keys[i]);
    }
    for (std::size_t i = 0; i < s.ends.size(); ++i) {
      if (!tree.computeRayKeys(origin, s.ends[i], s.ray)) continue;
      for (const octomap::OcTreeKey& key : s.ray) {
        if (mark(key)) s.free_keys.push_back(key);
      }
    }
  } else {
    s.octomap_cloud.clear();
    s.octomap_cloud.reserve(s.ends.size());
    for (std::size_t i = 0; i < s.ends.size(); ++i) {
      const Eigen::Vector3f& p = s.points_world[s.end_source[i]];
      s.octomap_cloud.push_back(p.x(), p.y(), p.z());
    }
    octomap::KeySet free_cells;
    octomap::KeySet occupied_cells;
    if (config_.insertion == InsertionMethod::kOctomapDiscrete) {
      tree.computeDiscreteUpdate(s.octomap_cloud, origin, free_cells, occupied_cells,
                                 config_.max_range_m);
    } else {
      tree.computeUpdate(s.octomap_cloud, origin, free_cells, occupied_cells, config_.max_range_m);
    }
    s.free_keys.assign(free_cells.begin(), free_cells.end());
    s.occupied_keys.assign(occupied_cells.begin(), occupied_cells.end());
  }

  result.raycast_ms = msSince(start);
  const auto update_start = Clock::now();
  result.free_voxels = s.free_keys.size();
  result.occupied_voxels = s.occupied_keys.size();
  if (contribution == Contribution::kTakeOut) {
    // The same keys as when the cloud went in at this pose, with the negated updates. A voxel
    // back at exactly zero was seen by nothing else: it is unknown again.
    std::vector<octomap::OcTreeKey> emptied;
    const auto take_out = [&](const octomap::OcTreeKey& key, float log_odds) {
      const auto* node = tree.updateNode(key, -log_odds, true);
      if (node != nullptr && std::abs(node->getLogOdds()) < kEmptyLogOdds) emptied.push_back(key);
    };
    for (const octomap::OcTreeKey& key : s.free_keys) take_out(key, tree.getProbMissLog());
    for (const octomap::OcTreeKey& key : s.occupied_keys) take_out(key, tree.getProbHitLog());
    for (const octomap::OcTreeKey& key : emptied) {
      const auto* node = tree.search(key);
      if (node != nullptr && std::abs(node->getLogOdds()) < kEmptyLogOdds) deleteVoxel(tree, key);
    }
    voxels_deleted_ = voxels_deleted_ || !emptied.empty();
    result.update_ms = msSince(update_start);
    return;
  }
  // Lazy evaluation: leaves only; inner nodes are refreshed when read (ensureInnerOccupancy).
  for (const octomap::OcTreeKey& key : s.free_keys) tree.updateNode(key, false, true);
  for (const octomap::OcTreeKey& key : s.occupied_keys) tree.updateNode(key, true, true);

  if constexpr (std::is_same_v<Tree, octomap::ColorOcTree>) {
    if (cloud_camera.hasColor()) {
      for (std::size_t i = 0; i < s.end_keys.size(); ++i) {
        if (!s.end_occupied[i]) continue;
        const ColorBgr& c = cloud_camera.colors_bgr[s.end_source[i]];
        tree.averageNodeColor(s.end_keys[i], c[2], c[1], c[0]);
      }
    }
  }
  result.update_ms = msSince(update_start);
}

bool Mapper::admitKeyframeCloud(std::int64_t bytes, std::int64_t freed_bytes) {
  const std::int64_t budget = std::int64_t{config_.keyframe_cloud_budget_mb} << 20;
  if (memory_pressure_ != MemoryPressure::kNone ||
      stats_.keyframe_cloud_bytes - freed_bytes + bytes > budget) {
    ++stats_.keyframe_clouds_refused;
    return false;
  }
  return true;
}

bool Mapper::keepKeyframe(std::int64_t id, const PointCloud& cloud, const SE3& T_world_camera,
                          Utime utime) {
  if (!config_.keep_keyframe_clouds) return false;
  const auto existing = keyframes_.find(id);
  const std::int64_t freed =
      existing != keyframes_.end() ? cloudBytes(existing->second.cloud_camera) : 0;
  if (!admitKeyframeCloud(cloudBytes(cloud), freed)) return false;
  KeyframeCloud& kept = keyframes_[id];
  kept = KeyframeCloud{};
  // Sorted by elevation (image row), so that each part is a band of the image: rays of different
  // parts then cross few voxels in common (each part's voxels are counted once, like a frame's).
  std::vector<std::uint32_t> order(cloud.size());
  std::vector<float> elevation(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    order[i] = static_cast<std::uint32_t>(i);
    elevation[i] = std::atan2(cloud.points[i].y(), cloud.points[i].z());
  }
  std::stable_sort(order.begin(), order.end(), [&elevation](std::uint32_t a, std::uint32_t b) {
    return elevation[a] < elevation[b];
  });
  const bool with_color = cloud.hasColor();
  kept.cloud_camera.points.reserve(cloud.size());
  for (const std::uint32_t i : order) {
    kept.cloud_camera.points.push_back(cloud.points[i]);
    if (with_color) kept.cloud_camera.colors_bgr.push_back(cloud.colors_bgr[i]);
    kept.farthest_point_m =
        std::max(kept.farthest_point_m, static_cast<double>(cloud.points[i].norm()));
  }
  kept.part_points = static_cast<std::size_t>(config_.keyframe_step_points);
  kept.parts = static_cast<int>(partsOf(cloud.size(), kept.part_points));
  kept.T_world_camera = T_world_camera;
  kept.T_world_camera_in_map = T_world_camera;
  kept.utime = utime;
  stats_.keyframe_cloud_bytes += cloudBytes(cloud) - freed;
  stats_.keyframe_clouds = static_cast<std::int64_t>(keyframes_.size());
  return true;
}

// --- outputs -------------------------------------------------------------------------------------

MapUpdate Mapper::takeUpdate() {
  MapUpdate update;
  update.utime = latest_utime_;
  update.resolution_m = resolution();
  update.frame_id = config_.frame_id;
  const bool new_free = config_.update_new_free_voxels;
  withTree([&update, new_free](auto& tree) {
    update.voxels.reserve(tree.numChangesDetected());
    for (auto it = tree.changedKeysBegin(); it != tree.changedKeysEnd(); ++it) {
      // search() finds the leaf (or the pruned ancestor holding its value); inner nodes are not
      // needed, so lazy evaluation is no obstacle.
      const auto* node = tree.search(it->first);
      if (node == nullptr) continue;
      // it->second: true for a newly created voxel, false for an occupancy flip.
      if (!new_free && it->second && !tree.isNodeOccupied(node)) continue;
      const octomap::point3d c = tree.keyToCoord(it->first);
      update.voxels.push_back({Eigen::Vector3f(c.x(), c.y(), c.z()), node->getLogOdds()});
    }
    tree.resetChangeDetection();
  });
  // Only updates with voxels are sent (MappingStep::publishOutputs), so only they take a sequence
  // number: a number taken by an update never sent (new free voxels only, which are not sent)
  // would look like a lost message to subscribers, who would then wait for a full map.
  update.sequence = next_update_sequence_;
  if (update.voxels.empty()) return update;
  ++next_update_sequence_;
  ++stats_.updates_published;
  return update;
}

FullMap Mapper::fullMap() {
  FullMap map;
  map.utime = latest_utime_;
  map.resolution_m = resolution();
  map.frame_id = config_.frame_id;
  map.update_sequence = next_update_sequence_;
  std::ostringstream stream(std::ios::binary);
  withTree([&stream](auto& tree) {
    tree.prune();
    tree.writeBinaryData(stream);
  });
  const std::string bytes = stream.str();
  map.data.assign(bytes.begin(), bytes.end());
  ++stats_.full_maps_published;
  return map;
}

MapperOutputs Mapper::poll(Utime now) {
  MapperOutputs out;
  // Periods run on message time. The first call starts each clock; a clock that goes backwards
  // (a log replayed again) restarts.
  const auto due = [now](std::optional<Utime>& last, double period_s, bool fire_first) {
    if (!(period_s > 0.0)) return false;
    if (!last || now < *last) {
      last = now;
      return fire_first;
    }
    // 1 ms of slack: frame stamps jitter, and 30 Hz stamps are 33,333 us apart, so a 10 Hz
    // output would otherwise wait for every fourth frame instead of every third.
    if (static_cast<double>(now - *last) >= period_s * 1e6 - 1000.0) {
      last = now;
      return true;
    }
    return false;
  };
  const auto pending = [this]() {
    return withTree([](const auto& tree) { return tree.numChangesDetected(); }) > 0;
  };
  const bool updates_on = config_.update_rate_hz > 0.0;
  if (updates_on && due(last_update_time_, 1.0 / config_.update_rate_hz, true) && pending()) {
    out.update = takeUpdate();
  }
  if (due(last_full_map_time_, config_.full_map_period_s, false) || full_map_requested_) {
    last_full_map_time_ = now;
    if (updates_on && !out.update && pending()) out.update = takeUpdate();
    out.full_map = fullMap();
    full_map_requested_ = false;
  }
  if (!config_.snapshot_path.empty()) {
    // A failed snapshot (a full disk, a folder gone) is retried sooner than the next period:
    // after 1 s, then 2, 4, ... up to the period. The map stays in memory meanwhile, and the
    // previous snapshot file stays intact (writes go through a temporary file).
    // While failing, the retry schedule replaces the period.
    const bool retry_due = snapshot_retry_at_ && now >= *snapshot_retry_at_;
    if (retry_due ||
        (!snapshot_retry_at_ && due(last_snapshot_time_, config_.snapshot_period_s, false))) {
      if (retry_due) ++stats_.snapshot_retries;
      out.snapshot = saveSnapshot();
      if (out.snapshot->ok) {
        last_snapshot_time_ = now;
        snapshot_retry_at_.reset();
        snapshot_retry_delay_s_ = kFirstSnapshotRetryDelayS;
      } else {
        snapshot_retry_at_ = now + static_cast<Utime>(snapshot_retry_delay_s_ * 1e6);
        snapshot_retry_delay_s_ =
            std::min(2.0 * snapshot_retry_delay_s_,
                     std::max(config_.snapshot_period_s, kFirstSnapshotRetryDelayS));
      }
    }
  }
  return out;
}

OccupancyGrid2D Mapper::projectToGrid() {
  return projectToGrid(config_.up_axis, config_.projection_min_height_m,
                       config_.projection_max_height_m);
}

OccupancyGrid2D Mapper::projectToGrid(UpAxis up_axis, double min_height_m, double max_height_m) {
  OccupancyGrid2D grid;
  grid.up_axis = up_axis;
  grid.min_height_m = min_height_m;
  grid.max_height_m = max_height_m;
  const double res = resolution();
  grid.resolution_m = res;
  const Eigen::Matrix3d R = gridAxes(up_axis);
  struct Footprint {
    double u0, v0;  // lower corner, metres
    int cells;      // edge in cells
    bool occupied;
  };
  std::vector<Footprint> footprints;
  withTree([&](const auto& tree) {
    for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
      const double size = it.getSize();
      const octomap::point3d c = it.getCoordinate();
      const Eigen::Vector3d g = R * Eigen::Vector3d(c.x(), c.y(), c.z());
      if (g.z() + 0.5 * size <= min_height_m || g.z() - 0.5 * size >= max_height_m) continue;
      footprints.push_back({g.x() - 0.5 * size, g.y() - 0.5 * size,
                            static_cast<int>(std::lround(size / res)), tree.isNodeOccupied(*it)});
    }
  });
  if (footprints.empty()) return grid;
  double u_min = std::numeric_limits<double>::max();
  double v_min = u_min;
  double u_max = -u_min;
  double v_max = -u_min;
  for (const Footprint& f : footprints) {
    u_min = std::min(u_min, f.u0);
    v_min = std::min(v_min, f.v0);
    u_max = std::max(u_max, f.u0 + f.cells * res);
    v_max = std::max(v_max, f.v0 + f.cells * res);
  }
  // Voxel faces lie on multiples of the resolution; snap away float noise.
  grid.origin_u_m = std::round(u_min / res) * res;
  grid.origin_v_m = std::round(v_min / res) * res;
  const long cols = std::lround((u_max - grid.origin_u_m) / res);
  const long rows = std::lround((v_max - grid.origin_v_m) / res);
  if (cols <= 0 || rows <= 0 || cols * rows > 400'000'000L) return grid;
  grid.cells = cv::Mat(static_cast<int>(rows), static_cast<int>(cols), CV_8UC1,
                       cv::Scalar(OccupancyGrid2D::kUnknown));
  // Free first, then occupied: any occupied voxel in the band makes its column an obstacle.
  for (const bool occupied_pass : {false, true}) {
    for (const Footprint& f : footprints) {
      if (f.occupied != occupied_pass) continue;
      const long ix0 = std::lround((f.u0 - grid.origin_u_m) / res);
      const long iy0 = std::lround((f.v0 - grid.origin_v_m) / res);
      for (long iy = std::max(0L, iy0); iy < std::min(rows, iy0 + f.cells); ++iy) {
        auto* row = grid.cells.ptr<std::uint8_t>(static_cast<int>(iy));
        for (long ix = std::max(0L, ix0); ix < std::min(cols, ix0 + f.cells); ++ix) {
          if (occupied_pass) {
            row[ix] = OccupancyGrid2D::kOccupied;
          } else if (row[ix] == OccupancyGrid2D::kUnknown) {
            row[ix] = OccupancyGrid2D::kFree;
          }
        }
      }
    }
  }
  return grid;
}

PointCloud Mapper::occupiedCloud() {
  PointCloud cloud;
  const double res = resolution();
  withTree([&](const auto& tree) {
    using NodeT = std::decay_t<decltype(*tree.begin_leafs())>;
    for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
      if (!tree.isNodeOccupied(*it)) continue;
      ColorBgr color{255, 255, 255};
      if constexpr (std::is_same_v<NodeT, octomap::ColorOcTreeNode>) {
        const octomap::ColorOcTreeNode::Color c = it->getColor();
        color = {c.b, c.g, c.r};
      }
      // A pruned occupied leaf stands for n^3 finest voxels.
      const int n = static_cast<int>(std::lround(it.getSize() / res));
      const octomap::point3d c = it.getCoordinate();
      const double half = 0.5 * it.getSize();
      const double corner[3] = {static_cast<double>(c.x()) - half,
                                static_cast<double>(c.y()) - half,
                                static_cast<double>(c.z()) - half};
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          for (int k = 0; k < n; ++k) {
            cloud.points.emplace_back(static_cast<float>(corner[0] + (i + 0.5) * res),
                                      static_cast<float>(corner[1] + (j + 0.5) * res),
                                      static_cast<float>(corner[2] + (k + 0.5) * res));
            cloud.colors_bgr.push_back(color);
          }
        }
      }
    }
  });
  return cloud;
}

MapFileResult Mapper::exportOccupiedPly(const std::string& path, PlyFormat format) {
  const auto start = Clock::now();
  MapFileResult result;
  result.path = path;
  const PointCloud cloud = occupiedCloud();
  result.ok = writeFileAtomically(
      path, [&](std::ostream& out) { return writePly(out, cloud, format); }, &result.error);
  result.seconds = secondsSince(start);
  return result;
}

MapFileResult Mapper::exportKeyframeCloudPly(const std::string& path, double voxel_m,
                                             PlyFormat format) {
  const auto start = Clock::now();
  MapFileResult result;
  result.path = path;
  PointCloud merged;
  bool all_colored = true;
  for (const auto& entry : keyframes_)
    all_colored = all_colored && entry.second.cloud_camera.hasColor();
  for (const auto& entry : keyframes_) {
    const KeyframeCloud& kf = entry.second;
    const Eigen::Matrix3f R = kf.T_world_camera.linear().cast<float>();
    const Eigen::Vector3f t = kf.T_world_camera.translation().cast<float>();
    for (std::size_t i = 0; i < kf.cloud_camera.size(); ++i) {
      merged.points.push_back(R * kf.cloud_camera.points[i] + t);
      if (all_colored) merged.colors_bgr.push_back(kf.cloud_camera.colors_bgr[i]);
    }
  }
  PointCloud filtered;
  VoxelGridFilter filter;
  filter.apply(merged, voxel_m, VoxelFilterMode::kCentroid, filtered);
  result.ok = writeFileAtomically(
      path, [&](std::ostream& out) { return writePly(out, filtered, format); }, &result.error);
  result.seconds = secondsSince(start);
  return result;
}

// --- persistence ---------------------------------------------------------------------------------

MapFileResult Mapper::saveMap(const std::string& path) {
  const auto start = Clock::now();
  MapFileResult result;
  result.path = path;
  const std::string extension = extensionOf(path);
  if (extension == ".bt" || extension == ".ot") {
    const bool full = extension == ".ot";
    // .ot stores inner nodes too, so they must be current; .bt stores leaves only.
    if (full) ensureInnerOccupancy();
    withTree([](auto& tree) { tree.prune(); });
    result.ok = writeFileAtomically(
        path,
        [this, full](std::ostream& out) {
          return withTree([&out, full](const auto& tree) {
            return full ? tree.write(out) : tree.writeBinaryConst(out);
          });
        },
        &result.error);
  } else {
    result.error = path + ": map files must end in .bt or .ot";
  }
  result.seconds = secondsSince(start);
  return result;
}

MapFileResult Mapper::saveMaps(const std::string& prefix) {
  const MapFileResult binary = saveMap(prefix + ".bt");
  if (!binary.ok) return binary;
  return saveMap(prefix + ".ot");
}

MapFileResult Mapper::saveSnapshot() {
  if (config_.snapshot_path.empty()) {
    MapFileResult result;
    result.error = "no snapshot path configured (mapping.snapshot_path)";
    ++stats_.snapshot_failures;
    return result;
  }
  MapFileResult result = saveMap(config_.snapshot_path);
  ++(result.ok ? stats_.snapshots_written : stats_.snapshot_failures);
  return result;
}

MapFileResult Mapper::loadMap(const std::string& path) {
  const auto start = Clock::now();
  MapFileResult result;
  result.path = path;
  const std::string extension = extensionOf(path);
  std::unique_ptr<octomap::OcTree> plain;
  std::unique_ptr<octomap::ColorOcTree> colored;
  if (extension != ".bt" && extension != ".ot") {
    result.error = path + ": map files must end in .bt or .ot";
    return result;
  }
  // The file is read whole and checked before OctoMap's reader, which trusts its input, sees it.
  std::vector<std::uint8_t> bytes;
  OctomapFileHeader header;
  std::string problem;
  if (!readFileBytes(path, bytes, problem)) {
    result.error = problem;
    return result;
  }
  if (!checkOctomapFile(bytes.data(), bytes.size(), header, &problem)) {
    result.error = path + ": " + problem;
    return result;
  }
  if (header.binary != (extension == ".bt")) {
    result.error = path + ": the file holds a " + (header.binary ? ".bt" : ".ot") +
                   " map but is named " + extension;
    return result;
  }
  std::istringstream in(std::string(bytes.begin(), bytes.end()), std::ios::binary);
  bytes = {};
  if (header.binary) {
    bool ok = false;
    if (config_.color) {
      colored = std::make_unique<octomap::ColorOcTree>(config_.resolution_m);
      ok = colored->readBinary(in);
    } else {
      plain = std::make_unique<octomap::OcTree>(config_.resolution_m);
      ok = plain->readBinary(in);
    }
    if (!ok) {
      result.error = path + " is not a readable OctoMap binary (.bt) file";
      return result;
    }
  } else {
    std::unique_ptr<octomap::AbstractOcTree> any(octomap::AbstractOcTree::read(in));
    if (auto* p = dynamic_cast<octomap::ColorOcTree*>(any.get())) {
      any.release();
      colored.reset(p);
    } else if (auto* q = dynamic_cast<octomap::OcTree*>(any.get())) {
      any.release();
      plain.reset(q);
    } else {
      result.error = path + " is not a readable OcTree or ColorOcTree (.ot) file";
      return result;
    }
  }
  tree_ = std::move(plain);
  color_tree_ = std::move(colored);
  forgetKeyframeClouds();
  inner_dirty_ = false;
  afterMapReplaced();
  result.ok = true;
  result.seconds = secondsSince(start);
  return result;
}

void Mapper::afterMapReplaced() {
  configureTree();
  requestResynchronisation();
  frames_since_prune_ = 0;
}

void Mapper::requestResynchronisation() {
  // Deletions cannot be expressed as updates: skip one sequence number so that subscribers see
  // a gap and resynchronise from the full map requested here.
  ++next_update_sequence_;
  full_map_requested_ = true;
  voxels_deleted_ = false;
}

void Mapper::forgetKeyframeClouds() {
  keyframes_.clear();
  keyframes_queued_.clear();
  stats_.keyframe_clouds = 0;
  stats_.keyframe_cloud_bytes = 0;
}

// --- following corrections ----------------------------------------------------------------------

void Mapper::queueKeyframe(double priority, std::int64_t id) {
  // Sorted by (priority, id): the back is done first (highest priority, then newest).
  const std::pair<double, std::int64_t> entry{priority, id};
  keyframes_queued_.insert(
      std::upper_bound(keyframes_queued_.begin(), keyframes_queued_.end(), entry), entry);
}

KeyframeCorrectionResult Mapper::correctKeyframePoses(
    const std::vector<std::pair<std::int64_t, SE3>>& keyframe_poses) {
  KeyframeCorrectionResult result;
  for (const auto& [id, pose] : keyframe_poses) {
    const auto it = keyframes_.find(id);
    if (it == keyframes_.end() || it->second.to_forget || !poseError(pose).empty()) {
      ++result.unknown_ids;
      continue;
    }
    it->second.T_world_camera = pose;
  }
  // The queue is rebuilt from every kept keyframe: one queued earlier may have been corrected
  // back to where it is in the map, and each moves once, to its newest pose.
  keyframes_queued_.clear();
  const double half_voxel_m = 0.5 * resolution();
  for (auto& [id, keyframe] : keyframes_) {
    if (keyframe.to_forget || keyframe.parts_in_map == 0) {
      // To forget, new, or taken out by a move: first. The last goes in at its newest pose.
      keyframes_queued_.emplace_back(kFirst, id);
      if ((keyframe.moving || keyframe.to_move) && !keyframe.to_forget) ++result.keyframes_to_move;
      continue;
    }
    const SE3 delta = keyframe.T_world_camera_in_map.inverse() * keyframe.T_world_camera;
    const double angle_rad = Eigen::AngleAxisd(delta.linear()).angle();
    const double largest_shift_m =
        delta.translation().norm() + keyframe.farthest_point_m * angle_rad;
    keyframe.to_move = largest_shift_m > half_voxel_m;
    if (keyframe.to_move) ++result.keyframes_to_move;
    const bool partly_in = keyframe.parts_in_map < keyframe.parts;
    if (partly_in) {
      keyframes_queued_.emplace_back(kFirst, id);  // finish what was started
    } else if (keyframe.to_move) {
      keyframes_queued_.emplace_back(largest_shift_m, id);
    }
  }
  std::sort(keyframes_queued_.begin(), keyframes_queued_.end());
  return result;
}

CatchUpResult Mapper::catchUp(double budget_s) {
  const auto start = Clock::now();
  CatchUpResult result;
  while (!keyframes_queued_.empty() && budget_s > 0.0) {
    // A step is started only when one like the last fits in what is left of the budget.
    if (result.steps > 0 && secondsSince(start) + last_step_s_ > budget_s) break;
    const auto step_start = Clock::now();
    const std::int64_t id = keyframes_queued_.back().second;
    if (keyframeStep(id, result)) keyframes_queued_.pop_back();
    last_step_s_ = secondsSince(step_start);
  }
  result.keyframes_left = keyframes_queued_.size();
  result.caught_up = result.steps > 0 && keyframes_queued_.empty();
  if (result.caught_up) ++stats_.corrections_caught_up;
  // Voxels that became unknown (here or in forgetKeyframe()) reach subscribers once the map has
  // caught up, through one full map.
  if (keyframes_queued_.empty() && voxels_deleted_) requestResynchronisation();
  result.seconds = secondsSince(start);
  return result;
}

bool Mapper::keyframeStep(std::int64_t id, CatchUpResult& result) {
  const auto it = keyframes_.find(id);
  if (it == keyframes_.end()) return true;  // forgotten since it was queued
  KeyframeCloud& keyframe = it->second;
  const bool wholly_in_place =
      !keyframe.to_forget && !keyframe.to_move && keyframe.parts_in_map == keyframe.parts;
  if (wholly_in_place) return true;  // queued twice (an id integrated again): nothing to do
  ++result.steps;
  if ((keyframe.to_forget || keyframe.to_move) && keyframe.parts_in_map > 0) {
    --keyframe.parts_in_map;
    putPart(keyframe, keyframe.parts_in_map, Contribution::kTakeOut);
    return false;
  }
  if (keyframe.to_forget) {
    eraseKeyframe(it);
    ++stats_.keyframes_taken_out;
    return true;
  }
  if (keyframe.to_move) {
    keyframe.to_move = false;
    keyframe.moving = true;
  }
  if (keyframe.parts_in_map == 0) keyframe.T_world_camera_in_map = keyframe.T_world_camera;
  putPart(keyframe, keyframe.parts_in_map, Contribution::kPutIn);
  ++keyframe.parts_in_map;
  if (keyframe.parts_in_map < keyframe.parts) return false;
  if (keyframe.moving) {
    keyframe.moving = false;
    ++result.keyframes_moved;
    ++stats_.keyframes_moved;
  } else {
    ++result.keyframes_added;
  }
  return true;
}

void Mapper::putPart(const KeyframeCloud& keyframe, int part, Contribution contribution) {
  const std::size_t size = keyframe.cloud_camera.size();
  const std::size_t first = std::min(size, static_cast<std::size_t>(part) * keyframe.part_points);
  const std::size_t last = std::min(size, first + keyframe.part_points);
  part_.points.assign(keyframe.cloud_camera.points.begin() + first,
                      keyframe.cloud_camera.points.begin() + last);
  part_.colors_bgr.clear();
  if (keyframe.cloud_camera.hasColor()) {
    part_.colors_bgr.assign(keyframe.cloud_camera.colors_bgr.begin() + first,
                            keyframe.cloud_camera.colors_bgr.begin() + last);
  }
  // Putting in or taking out a kept cloud is not new data: the per-frame totals stay as they
  // were. A part that cannot go in (origin off the map, no points) cannot come out either.
  const MapperStats saved_stats = stats_;
  insertCameraCloud(part_, keyframe.T_world_camera_in_map, {}, contribution);
  stats_ = saved_stats;
}

void Mapper::forgetKeyframeInSteps(std::int64_t keyframe_id) {
  const auto it = keyframes_.find(keyframe_id);
  if (it == keyframes_.end() || it->second.to_forget) return;
  it->second.to_forget = true;
  queueKeyframe(kFirst, keyframe_id);
}

void Mapper::forgetKeyframe(std::int64_t keyframe_id) {
  const auto it = keyframes_.find(keyframe_id);
  if (it == keyframes_.end()) return;
  KeyframeCloud& keyframe = it->second;
  if (keyframe.parts_in_map > 0) ++stats_.keyframes_taken_out;
  while (keyframe.parts_in_map > 0) {
    --keyframe.parts_in_map;
    putPart(keyframe, keyframe.parts_in_map, Contribution::kTakeOut);
  }
  eraseKeyframe(it);
  // A queued entry for it is skipped when it comes up.
}

void Mapper::eraseKeyframe(std::map<std::int64_t, KeyframeCloud>::iterator it) {
  stats_.keyframe_cloud_bytes -= cloudBytes(it->second.cloud_camera);
  keyframes_.erase(it);
  stats_.keyframe_clouds = static_cast<std::int64_t>(keyframes_.size());
}

CoarsenResult Mapper::coarsenFarMap(const Eigen::Vector3d& near_point_m) {
  const auto start = Clock::now();
  CoarsenResult result;
  if (config_.coarse_far_levels <= 0 || !near_point_m.allFinite()) return result;
  // A voxel a ray touches lies within one voxel of the ray.
  const double margin_m = resolution();
  std::vector<Eigen::AlignedBox3d> kept_boxes;
  for (const auto& entry : keyframes_) {
    const KeyframeCloud& keyframe = entry.second;
    if (keyframe.parts_in_map == 0) continue;
    kept_boxes.push_back(reachOf(keyframe.cloud_camera, keyframe.T_world_camera_in_map,
                                 config_.max_range_m, margin_m));
  }
  result = withTree([&](auto& tree) {
    return FarMapCoarsener(tree, near_point_m, config_.coarse_far_radius_m,
                           config_.coarse_far_levels, std::move(kept_boxes))
        .run();
  });
  if (result.blocks_merged > 0) {
    ++stats_.far_map_coarsenings;
    stats_.far_map_blocks_merged += static_cast<std::int64_t>(result.blocks_merged);
    inner_dirty_ = true;
    requestResynchronisation();
  }
  result.seconds = secondsSince(start);
  return result;
}

std::size_t Mapper::releaseKeyframeClouds(std::size_t keep_newest) {
  std::size_t oldest = keyframes_.size() > keep_newest ? keyframes_.size() - keep_newest : 0;
  std::size_t released = 0;
  for (auto it = keyframes_.begin(); oldest > 0 && it != keyframes_.end(); --oldest) {
    const KeyframeCloud& keyframe = it->second;
    const bool settled = keyframe.parts_in_map == keyframe.parts && !keyframe.to_move &&
                         !keyframe.moving && !keyframe.to_forget;
    if (!settled) {
      ++it;
      continue;
    }
    eraseKeyframe(it++);
    ++released;
    ++stats_.keyframe_clouds_released;
  }
  return released;
}

std::vector<std::int64_t> Mapper::keptKeyframeIds() const {
  std::vector<std::int64_t> ids;
  ids.reserve(keyframes_.size());
  for (const auto& entry : keyframes_) ids.push_back(entry.first);
  return ids;
}

std::vector<KeyframeCloudRecord> Mapper::keyframeCloudRecords() const {
  std::vector<KeyframeCloudRecord> records;
  records.reserve(keyframes_.size());
  for (const auto& [id, keyframe] : keyframes_) {
    if (keyframe.to_forget) continue;
    KeyframeCloudRecord& record = records.emplace_back();
    record.id = id;
    record.utime = keyframe.utime;
    record.cloud_camera = keyframe.cloud_camera;
    // With nothing in the map (new, or taken out by a move), it goes in at its newest pose next.
    record.T_world_camera_in_map =
        keyframe.parts_in_map > 0 ? keyframe.T_world_camera_in_map : keyframe.T_world_camera;
    record.part_points = keyframe.part_points;
    record.parts_in_map = keyframe.parts_in_map;
  }
  return records;
}

bool Mapper::isRestorable(const KeyframeCloudRecord& record) const {
  const PointCloud& cloud = record.cloud_camera;
  if (keyframes_.count(record.id) != 0 || !poseError(record.T_world_camera_in_map).empty() ||
      !originOnMap(record.T_world_camera_in_map) || cloud.empty() || record.part_points == 0) {
    return false;
  }
  if (cloud.hasColor() && cloud.colors_bgr.size() != cloud.points.size()) return false;
  for (const Eigen::Vector3f& p : cloud.points) {
    if (!p.allFinite() || p.cwiseAbs().maxCoeff() > kMaxRecordPointM) return false;
  }
  const std::size_t parts = partsOf(cloud.size(), record.part_points);
  return parts <= static_cast<std::size_t>(std::numeric_limits<int>::max()) &&
         record.parts_in_map >= 0 && static_cast<std::size_t>(record.parts_in_map) <= parts;
}

std::size_t Mapper::restoreKeyframeClouds(std::vector<KeyframeCloudRecord> records) {
  if (!config_.keep_keyframe_clouds) return 0;
  std::size_t kept = 0;
  for (KeyframeCloudRecord& record : records) {
    if (!isRestorable(record)) {
      ++stats_.keyframe_clouds_invalid;
      continue;
    }
    const std::int64_t bytes = cloudBytes(record.cloud_camera);
    if (!admitKeyframeCloud(bytes, 0)) continue;
    KeyframeCloud& keyframe = keyframes_[record.id];
    // The cloud is already in the mapper's part order: parts cut from it now are the parts that
    // went into the map, so each can be taken out exactly.
    keyframe.cloud_camera = std::move(record.cloud_camera);
    for (const Eigen::Vector3f& p : keyframe.cloud_camera.points) {
      keyframe.farthest_point_m =
          std::max(keyframe.farthest_point_m, static_cast<double>(p.norm()));
    }
    keyframe.part_points = record.part_points;
    keyframe.parts = static_cast<int>(partsOf(keyframe.cloud_camera.size(), record.part_points));
    keyframe.parts_in_map = record.parts_in_map;
    keyframe.T_world_camera = record.T_world_camera_in_map;
    keyframe.T_world_camera_in_map = record.T_world_camera_in_map;
    keyframe.utime = record.utime;
    if (keyframe.parts_in_map < keyframe.parts) queueKeyframe(kFirst, record.id);
    stats_.keyframe_cloud_bytes += bytes;
    stats_.keyframe_clouds = static_cast<std::int64_t>(keyframes_.size());
    ++kept;
  }
  return kept;
}

void Mapper::reset() {
  forgetKeyframeClouds();
  makeEmptyTree(resolution(), hasColor());
  afterMapReplaced();
}

}  // namespace slamd
