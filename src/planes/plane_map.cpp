#include "slamd/planes/plane_map.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <utility>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "slamd/common/file_io.hpp"

namespace slamd::planes {

namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

/// Rays within about 3 degrees of a plane meet it ill-conditioned (|n.r| / |r| below this).
constexpr double kMinRayCosine = 0.05;

double angleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.dot(b), -1.0, 1.0)) / kDegToRad;
}

bool finite(const Plane& plane) {
  if (!plane.normal_camera.allFinite() || !std::isfinite(plane.offset_m) ||
      !plane.covariance.allFinite() || !plane.centroid_camera.allFinite() ||
      !std::isfinite(plane.area_m2)) {
    return false;
  }
  return std::all_of(plane.boundary_camera.begin(), plane.boundary_camera.end(),
                     [](const Eigen::Vector3d& p) { return p.allFinite(); });
}

/// Coordinates in a plane: origin on the plane, tangents t1, t2 with t1 x t2 = n.
struct PlaneFrame {
  Eigen::Vector3d origin;
  Eigen::Vector3d t1;
  Eigen::Vector3d t2;
  Eigen::Vector3d normal;

  PlaneFrame(const Eigen::Vector3d& n, double d, const Eigen::Vector3d& near_point)
      : t1(n.unitOrthogonal()), t2(n.cross(t1)), normal(n) {
    // The origin near the points keeps the float coordinates OpenCV's polygon functions use
    // precise far from the map's origin.
    origin = near_point - (n.dot(near_point) + d) * n;
  }
  cv::Point2f project(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d r = p - origin;
    return {static_cast<float>(r.dot(t1)), static_cast<float>(r.dot(t2))};
  }
  Eigen::Vector3d lift(const cv::Point2f& q) const {
    return origin + static_cast<double>(q.x) * t1 + static_cast<double>(q.y) * t2;
  }
};

/// Convex hull of points cast onto the plane, counter-clockwise seen from the normal's side.
std::vector<cv::Point2f> hullInPlane(const PlaneFrame& frame,
                                     const std::vector<Eigen::Vector3d>& points) {
  std::vector<cv::Point2f> projected;
  projected.reserve(points.size());
  for (const Eigen::Vector3d& p : points) projected.push_back(frame.project(p));
  std::vector<cv::Point2f> hull;
  if (projected.size() >= 3) cv::convexHull(projected, hull, /*clockwise=*/false);
  return hull;
}

/// Distance in the plane between two convex polygons, 0 when they overlap or touch, metres.
double polygonGap(const std::vector<cv::Point2f>& a, const std::vector<cv::Point2f>& b) {
  if (a.size() < 3 || b.size() < 3) return std::numeric_limits<double>::infinity();
  std::vector<cv::Point2f> overlap;
  if (cv::intersectConvexConvex(a, b, overlap, /*handleNested=*/true) > 0.0f) return 0.0;
  // Disjoint convex polygons: the nearest points include a vertex of one of them.
  double gap = std::numeric_limits<double>::infinity();
  for (const cv::Point2f& p : a) gap = std::min(gap, -cv::pointPolygonTest(b, p, true));
  for (const cv::Point2f& p : b) gap = std::min(gap, -cv::pointPolygonTest(a, p, true));
  return std::max(gap, 0.0);
}

}  // namespace

std::string PlaneMapParams::validationError() const {
  std::ostringstream out;
  if (!(max_angle_deg > 0.0 && max_angle_deg <= 45.0)) {
    out << "max_angle_deg = " << max_angle_deg << ": must be in (0, 45] degrees";
  } else if (!(max_distance_m > 0.0 && max_distance_m <= 1.0)) {
    out << "max_distance_m = " << max_distance_m << ": must be in (0, 1] metres";
  } else if (!(max_gap_m >= 0.0 && max_gap_m <= 10.0)) {
    out << "max_gap_m = " << max_gap_m << ": must be in [0, 10] metres";
  } else if (!(floor_angle_deg > 0.0 && floor_angle_deg <= 10.0)) {
    out << "floor_angle_deg = " << floor_angle_deg << ": must be in (0, 10] degrees";
  } else if (!(floor_offset_m > 0.0 && floor_offset_m <= 1.0)) {
    out << "floor_offset_m = " << floor_offset_m << ": must be in (0, 1] metres";
  } else if (!(min_area_m2 >= 0.0 && min_area_m2 <= 100.0)) {
    out << "min_area_m2 = " << min_area_m2 << ": must be in [0, 100] m^2";
  }
  return out.str();
}

// A keyframe plane moved into the map frame by its keyframe's pose.
struct PlaneMap::Member {
  std::int64_t keyframe_id = 0;
  int index = 0;  ///< in its keyframe
  Eigen::Vector3d normal;
  double offset_m = 0.0;
  Eigen::Matrix4d covariance;  ///< of (n, d), map frame
  Eigen::Vector3d centroid;
  double area_m2 = 0.0;
  std::vector<Eigen::Vector3d> boundary;
};

// A world plane being built: its members, their information-weighted fusion around the
// reference normal n0, and the hull of their boundaries.
struct PlaneMap::Cluster {
  std::vector<int> members;  ///< indices into the rebuild's member list
  Eigen::Vector3d n0 = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d t1 = Eigen::Vector3d::UnitX();
  Eigen::Vector3d t2 = Eigen::Vector3d::UnitY();
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();  ///< sum over members, of (a, b, e)
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();     ///< sum of information * (a, b, e)
  double area_sum = 0.0;
  Eigen::Vector3d area_centroid_sum = Eigen::Vector3d::Zero();
  // The fused plane and its polygon (hull vertices lifted onto the plane).
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset_m = 0.0;
  std::vector<Eigen::Vector3d> hull;

  Eigen::Vector3d centroid() const {
    const Eigen::Vector3d mean = area_centroid_sum / std::max(area_sum, 1e-12);
    return mean - (normal.dot(mean) + offset_m) * normal;
  }
  void setReference(const Eigen::Vector3d& n) {
    n0 = n;
    t1 = n.unitOrthogonal();
    t2 = n.cross(t1);
    information.setZero();
    weighted.setZero();
  }
  /// Adds a member's (a, b, e) with its information (see the header's fusion paragraph).
  void accumulate(const Member& m, const PlaneMapParams& params) {
    const double c = n0.dot(m.normal);  // > cos(45 deg) after the angle gate
    const double a = t1.dot(m.normal) / c;
    const double b = t2.dot(m.normal) / c;
    const double e = m.offset_m / c;
    Eigen::Matrix<double, 3, 4> J = Eigen::Matrix<double, 3, 4>::Zero();
    J.block<1, 3>(0, 0) = t1.transpose() / c - (a / c) * n0.transpose();
    J.block<1, 3>(1, 0) = t2.transpose() / c - (b / c) * n0.transpose();
    J.block<1, 3>(2, 0) = -(e / c) * n0.transpose();
    J(2, 3) = 1.0 / c;
    Eigen::Matrix3d covariance = J * m.covariance * J.transpose();
    // The floor: tilt and offset at the member's centroid, where e = h - n0.c - a t1.c - b t2.c.
    const double sigma_tilt = std::tan(params.floor_angle_deg * kDegToRad);
    const Eigen::Vector3d floor(sigma_tilt * sigma_tilt, sigma_tilt * sigma_tilt,
                                params.floor_offset_m * params.floor_offset_m);
    Eigen::Matrix3d G = Eigen::Matrix3d::Identity();
    G(2, 0) = -t1.dot(m.centroid);
    G(2, 1) = -t2.dot(m.centroid);
    covariance += G * floor.asDiagonal() * G.transpose();
    const Eigen::Matrix3d info = covariance.inverse();
    information += info;
    weighted += info * Eigen::Vector3d(a, b, e);
  }
  void solve() {
    const Eigen::Vector3d x = information.ldlt().solve(weighted);
    const Eigen::Vector3d m = n0 + x(0) * t1 + x(1) * t2;
    const double length = m.norm();
    normal = m / length;
    offset_m = x(2) / length;
  }
  /// Recomputes the fusion from all members around the current fused normal (the reference
  /// moves to where the members are, so the linearisation is about the result).
  void refuse(const std::vector<Member>& all, const PlaneMapParams& params) {
    for (int pass = 0; pass < 2; ++pass) {
      setReference(normal);
      for (const int i : members) accumulate(all[static_cast<std::size_t>(i)], params);
      solve();
    }
  }
  void rehull(const std::vector<Eigen::Vector3d>& more) {
    std::vector<Eigen::Vector3d> points = hull;
    points.insert(points.end(), more.begin(), more.end());
    const PlaneFrame frame(normal, offset_m, centroid());
    hull.clear();
    for (const cv::Point2f& q : hullInPlane(frame, points)) hull.push_back(frame.lift(q));
  }
};

PlaneMap::PlaneMap(const PlaneMapParams& params) : params_(params) {
  if (const std::string error = params.validationError(); !error.empty()) {
    throw std::invalid_argument("PlaneMapParams: " + error);
  }
}

void PlaneMap::addKeyframe(std::int64_t keyframe_id, const SE3& T_world_camera,
                           const std::vector<Plane>& planes_camera, Utime utime) {
  if (!T_world_camera.matrix().allFinite()) {
    ignored_planes_ += static_cast<std::int64_t>(planes_camera.size());
    return;
  }
  Keyframe keyframe;
  keyframe.T_world_camera = T_world_camera;
  keyframe.utime = utime;
  for (const Plane& plane : planes_camera) {
    if (!finite(plane) || plane.boundary_camera.size() < 3 ||
        std::abs(plane.normal_camera.norm() - 1.0) > 1e-6) {
      ++ignored_planes_;
      continue;
    }
    if (plane.area_m2 < params_.min_area_m2) continue;
    keyframe.planes.push_back(KeptPlane{plane.normal_camera, plane.offset_m, plane.covariance,
                                        plane.centroid_camera, plane.area_m2,
                                        plane.boundary_camera});
  }
  keyframes_[keyframe_id] = std::move(keyframe);
  dirty_ = true;
}

std::size_t PlaneMap::setKeyframePoses(
    const std::vector<std::pair<std::int64_t, SE3>>& keyframe_poses) {
  std::size_t moved = 0;
  for (const auto& [id, T_world_camera] : keyframe_poses) {
    const auto it = keyframes_.find(id);
    if (it == keyframes_.end() || !T_world_camera.matrix().allFinite()) continue;
    if (it->second.T_world_camera.matrix() == T_world_camera.matrix()) continue;
    it->second.T_world_camera = T_world_camera;
    ++moved;
  }
  if (moved > 0) dirty_ = true;
  return moved;
}

void PlaneMap::forgetKeyframe(std::int64_t keyframe_id) {
  if (keyframes_.erase(keyframe_id) > 0) dirty_ = true;
}

void PlaneMap::clear() {
  keyframes_.clear();
  world_planes_.clear();
  previous_id_.clear();
  dirty_ = false;
}

std::vector<std::int64_t> PlaneMap::keyframeIds() const {
  std::vector<std::int64_t> ids;
  ids.reserve(keyframes_.size());
  for (const auto& entry : keyframes_) ids.push_back(entry.first);
  return ids;
}

std::size_t PlaneMap::keyframePlaneCount() const {
  std::size_t count = 0;
  for (const auto& entry : keyframes_) count += entry.second.planes.size();
  return count;
}

const std::vector<WorldPlane>& PlaneMap::worldPlanes() {
  if (dirty_) rebuild();
  return world_planes_;
}

PlaneMapSnapshot PlaneMap::snapshot(const std::string& frame_id) {
  PlaneMapSnapshot snapshot;
  snapshot.frame_id = frame_id;
  snapshot.planes = worldPlanes();
  for (const auto& entry : keyframes_)
    snapshot.utime = std::max(snapshot.utime, entry.second.utime);
  return snapshot;
}

void PlaneMap::rebuild() {
  dirty_ = false;
  ++rebuilds_;
  // Every kept plane in the map frame, keyframe by keyframe, largest first within each.
  std::vector<Member> members;
  for (const auto& [id, keyframe] : keyframes_) {
    const Eigen::Matrix3d R = keyframe.T_world_camera.linear();
    const Eigen::Vector3d t = keyframe.T_world_camera.translation();
    // (n_w, d_w) = (R n_c, d_c - t.R n_c): the plane's equation for map-frame points.
    Eigen::Matrix4d J = Eigen::Matrix4d::Zero();
    J.block<3, 3>(0, 0) = R;
    J.block<1, 3>(3, 0) = -t.transpose() * R;
    J(3, 3) = 1.0;
    const std::size_t first = members.size();
    for (std::size_t i = 0; i < keyframe.planes.size(); ++i) {
      const KeptPlane& kept = keyframe.planes[i];
      Member m;
      m.keyframe_id = id;
      m.index = static_cast<int>(i);
      m.normal = R * kept.normal_camera;
      m.offset_m = kept.offset_m - m.normal.dot(t);
      m.covariance = J * kept.covariance * J.transpose();
      m.centroid = keyframe.T_world_camera * kept.centroid_camera;
      m.area_m2 = kept.area_m2;
      m.boundary.reserve(kept.boundary_camera.size());
      for (const Eigen::Vector3d& p : kept.boundary_camera) {
        m.boundary.push_back(keyframe.T_world_camera * p);
      }
      members.push_back(std::move(m));
    }
    std::stable_sort(members.begin() + static_cast<std::ptrdiff_t>(first), members.end(),
                     [](const Member& a, const Member& b) { return a.area_m2 > b.area_m2; });
  }

  const double max_angle = params_.max_angle_deg;
  const double max_distance = params_.max_distance_m;
  // Gate score of a plane (normal, centroid, boundary) against a cluster; < 0 when it fails.
  const auto score = [&](const Cluster& cluster, const Eigen::Vector3d& normal,
                         const Eigen::Vector3d& centroid,
                         const std::vector<Eigen::Vector3d>& boundary) {
    const double angle = angleBetweenDeg(normal, cluster.normal);
    if (angle > max_angle) return -1.0;
    const double distance = std::abs(cluster.normal.dot(centroid) + cluster.offset_m);
    if (distance > max_distance) return -1.0;
    const PlaneFrame frame(cluster.normal, cluster.offset_m, cluster.centroid());
    if (polygonGap(hullInPlane(frame, boundary), hullInPlane(frame, cluster.hull)) >
        params_.max_gap_m) {
      return -1.0;
    }
    return (angle / max_angle) * (angle / max_angle) +
           (distance / max_distance) * (distance / max_distance);
  };

  std::vector<Cluster> clusters;
  for (std::size_t i = 0; i < members.size(); ++i) {
    const Member& m = members[i];
    int best = -1;
    double best_score = std::numeric_limits<double>::infinity();
    for (std::size_t c = 0; c < clusters.size(); ++c) {
      const double s = score(clusters[c], m.normal, m.centroid, m.boundary);
      if (s >= 0.0 && s < best_score) {
        best = static_cast<int>(c);
        best_score = s;
      }
    }
    if (best < 0) {
      clusters.emplace_back();
      clusters.back().setReference(m.normal);
      best = static_cast<int>(clusters.size()) - 1;
    }
    Cluster& cluster = clusters[static_cast<std::size_t>(best)];
    cluster.members.push_back(static_cast<int>(i));
    cluster.accumulate(m, params_);
    cluster.solve();
    cluster.area_sum += m.area_m2;
    cluster.area_centroid_sum += m.area_m2 * m.centroid;
    cluster.rehull(m.boundary);
  }
  for (Cluster& cluster : clusters) {
    cluster.refuse(members, params_);
    cluster.rehull({});
  }

  // Clusters that match each other (parts first seen apart, joined by later keyframes).
  bool merged = true;
  while (merged) {
    merged = false;
    for (std::size_t i = 0; i < clusters.size() && !merged; ++i) {
      for (std::size_t j = i + 1; j < clusters.size() && !merged; ++j) {
        Cluster& a = clusters[i];
        Cluster& b = clusters[j];
        if (score(a, b.normal, b.centroid(), b.hull) < 0.0 ||
            score(b, a.normal, a.centroid(), a.hull) < 0.0) {
          continue;
        }
        a.members.insert(a.members.end(), b.members.begin(), b.members.end());
        a.area_sum += b.area_sum;
        a.area_centroid_sum += b.area_centroid_sum;
        std::vector<Eigen::Vector3d> b_hull = std::move(b.hull);
        a.refuse(members, params_);
        a.rehull(b_hull);
        clusters.erase(clusters.begin() + static_cast<std::ptrdiff_t>(j));
        merged = true;
      }
    }
  }

  // World planes, with the ids their members had last time where most of them agree.
  std::vector<WorldPlane> planes;
  std::vector<std::map<std::int64_t, int>> votes(clusters.size());
  for (std::size_t c = 0; c < clusters.size(); ++c) {
    const Cluster& cluster = clusters[c];
    WorldPlane plane;
    plane.normal_world = cluster.normal;
    plane.offset_m = cluster.offset_m;
    plane.polygon_world = cluster.hull;
    plane.centroid_world = cluster.centroid();
    plane.members = static_cast<int>(cluster.members.size());
    std::set<std::int64_t> keyframe_ids;
    for (const int i : cluster.members) {
      const Member& m = members[static_cast<std::size_t>(i)];
      keyframe_ids.insert(m.keyframe_id);
      const auto previous = previous_id_.find({m.keyframe_id, m.index});
      if (previous != previous_id_.end()) ++votes[c][previous->second];
    }
    plane.keyframe_ids.assign(keyframe_ids.begin(), keyframe_ids.end());
    const PlaneFrame frame(cluster.normal, cluster.offset_m, plane.centroid_world);
    const std::vector<cv::Point2f> hull = hullInPlane(frame, cluster.hull);
    plane.area_m2 = hull.size() >= 3 ? cv::contourArea(hull) : 0.0;
    planes.push_back(std::move(plane));
  }
  // A previous id goes to the plane with most members that had it; the others get new ones.
  std::vector<std::tuple<int, std::int64_t, std::size_t>> claims;  // (votes, id, plane)
  for (std::size_t c = 0; c < votes.size(); ++c) {
    for (const auto& [id, count] : votes[c]) claims.emplace_back(count, id, c);
  }
  std::sort(claims.begin(), claims.end(), [](const auto& x, const auto& y) {
    return std::get<0>(x) != std::get<0>(y) ? std::get<0>(x) > std::get<0>(y)
                                            : std::get<1>(x) < std::get<1>(y);
  });
  std::vector<bool> has_id(planes.size(), false);
  std::set<std::int64_t> taken;
  for (const auto& [count, id, c] : claims) {
    if (has_id[c] || taken.count(id) > 0) continue;
    planes[c].id = id;
    has_id[c] = true;
    taken.insert(id);
  }
  for (std::size_t c = 0; c < planes.size(); ++c) {
    if (!has_id[c]) planes[c].id = next_plane_id_++;
  }
  previous_id_.clear();
  for (std::size_t c = 0; c < clusters.size(); ++c) {
    for (const int i : clusters[c].members) {
      const Member& m = members[static_cast<std::size_t>(i)];
      previous_id_[{m.keyframe_id, m.index}] = planes[c].id;
    }
  }
  std::stable_sort(planes.begin(), planes.end(),
                   [](const WorldPlane& a, const WorldPlane& b) { return a.area_m2 > b.area_m2; });
  world_planes_ = std::move(planes);
}

double polygonGapM(const WorldPlane& a, const WorldPlane& b) {
  const PlaneFrame frame(a.normal_world, a.offset_m, a.centroid_world);
  return polygonGap(hullInPlane(frame, a.polygon_world), hullInPlane(frame, b.polygon_world));
}

DepthSnapStats snapDepthToPlanes(const cv::Mat& depth_m, const PlaneSegmentation& segmentation,
                                 const CameraIntrinsics& intrinsics, double max_sigmas,
                                 cv::Mat& snapped_depth_m) {
  if (depth_m.empty() || depth_m.type() != CV_32FC1 || segmentation.labels.type() != CV_32SC1 ||
      segmentation.labels.size() != depth_m.size() || depth_m.cols != intrinsics.width ||
      depth_m.rows != intrinsics.height) {
    throw std::invalid_argument(
        "snapDepthToPlanes: depth (CV_32FC1), labels (CV_32SC1) and intrinsics must have one "
        "size");
  }
  if (!(max_sigmas > 0.0)) {
    throw std::invalid_argument("snapDepthToPlanes: max_sigmas must be positive");
  }
  depth_m.copyTo(snapped_depth_m);
  DepthSnapStats stats;
  const int plane_count = static_cast<int>(segmentation.planes.size());
  for (int v = 0; v < depth_m.rows; ++v) {
    const int* labels = segmentation.labels.ptr<int>(v);
    float* depth = snapped_depth_m.ptr<float>(v);
    const double ry = (v - intrinsics.cy) / intrinsics.fy;
    for (int u = 0; u < depth_m.cols; ++u) {
      const int label = labels[u];
      const double z = depth[u];
      if (label < 0 || label >= plane_count || !(z > 0.0) || !std::isfinite(z)) continue;
      ++stats.labelled;
      const Plane& plane = segmentation.planes[static_cast<std::size_t>(label)];
      const Eigen::Vector3d ray((u - intrinsics.cx) / intrinsics.fx, ry, 1.0);
      const double n_dot_ray = plane.normal_camera.dot(ray);
      if (std::abs(n_dot_ray) < kMinRayCosine * ray.norm()) continue;
      const double z_plane = -plane.offset_m / n_dot_ray;
      if (!(z_plane > 0.0)) continue;
      if (std::abs(z - z_plane) > max_sigmas * kinectSigmaZ(z_plane)) continue;
      depth[u] = static_cast<float>(z_plane);
      ++stats.snapped;
    }
  }
  return stats;
}

namespace {

/// A colour per plane id, spread around the hue circle, as red, green, blue.
std::array<int, 3> planeColor(std::int64_t id) {
  const double hue = std::fmod(static_cast<double>(id) * 0.618033988749895, 1.0) * 6.0;
  const int sector = static_cast<int>(hue);
  const double f = hue - sector;
  const int up = static_cast<int>(55 + 200 * f);
  const int down = static_cast<int>(255 - 200 * f);
  switch (sector % 6) {
    case 0:
      return {255, up, 55};
    case 1:
      return {down, 255, 55};
    case 2:
      return {55, 255, up};
    case 3:
      return {55, down, 255};
    case 4:
      return {up, 55, 255};
    default:
      return {255, 55, down};
  }
}

}  // namespace

bool writePlaneMapPly(const std::string& path, const PlaneMapSnapshot& snapshot,
                      std::string* error) {
  std::size_t vertices = 0;
  std::size_t faces = 0;
  for (const WorldPlane& plane : snapshot.planes) {
    if (plane.polygon_world.size() < 3) continue;
    vertices += plane.polygon_world.size();
    ++faces;
  }
  return writeOutputFile(
      path,
      [&](std::ostream& out) {
        out << "ply\nformat ascii 1.0\n"
            << "comment slamd plane map: one face per plane, convex, in frame " << snapshot.frame_id
            << ", metres\n"
            << "comment utime " << snapshot.utime << "\n";
        out << std::setprecision(9);
        for (const WorldPlane& plane : snapshot.planes) {
          if (plane.polygon_world.size() < 3) continue;
          out << "comment plane " << plane.id << " offset_m " << plane.offset_m << " area_m2 "
              << plane.area_m2 << " keyframes " << plane.keyframe_ids.size() << "\n";
        }
        out << "element vertex " << vertices << "\n"
            << "property float x\nproperty float y\nproperty float z\n"
            << "element face " << faces << "\n"
            << "property list uchar int vertex_indices\n"
            << "property float nx\nproperty float ny\nproperty float nz\n"
            << "property uchar red\nproperty uchar green\nproperty uchar blue\n"
            << "end_header\n";
        for (const WorldPlane& plane : snapshot.planes) {
          if (plane.polygon_world.size() < 3) continue;
          for (const Eigen::Vector3d& p : plane.polygon_world) {
            out << static_cast<float>(p.x()) << ' ' << static_cast<float>(p.y()) << ' '
                << static_cast<float>(p.z()) << '\n';
          }
        }
        std::size_t next = 0;
        for (const WorldPlane& plane : snapshot.planes) {
          const std::size_t count = plane.polygon_world.size();
          if (count < 3) continue;
          // A uchar count: hulls of more than 255 vertices are not written whole.
          const std::size_t written = std::min<std::size_t>(count, 255);
          out << written;
          for (std::size_t k = 0; k < written; ++k) out << ' ' << next + k;
          next += count;
          const std::array<int, 3> color = planeColor(plane.id);
          out << ' ' << static_cast<float>(plane.normal_world.x()) << ' '
              << static_cast<float>(plane.normal_world.y()) << ' '
              << static_cast<float>(plane.normal_world.z()) << ' ' << color[0] << ' ' << color[1]
              << ' ' << color[2] << '\n';
        }
        return static_cast<bool>(out);
      },
      error);
}

bool readPlaneMapPly(const std::string& path, std::vector<PlyPolygon>& polygons,
                     std::string* error) {
  polygons.clear();
  const auto fail = [&](const std::string& why) {
    if (error) *error = path + ": " + why;
    polygons.clear();
    return false;
  };
  std::ifstream in(path);
  if (!in) return fail("cannot open");
  std::string line;
  if (!std::getline(in, line) || line != "ply") return fail("not a PLY file");
  if (!std::getline(in, line) || line != "format ascii 1.0") return fail("not ASCII PLY");
  long vertices = -1;
  long faces = -1;
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream words(line);
    std::string word, element;
    words >> word;
    if (word != "element") continue;
    long count = -1;
    words >> element >> count;
    if (element == "vertex") vertices = count;
    if (element == "face") faces = count;
  }
  if (line != "end_header" || vertices < 0 || faces < 0) return fail("bad header");
  std::vector<Eigen::Vector3d> points(static_cast<std::size_t>(vertices));
  for (Eigen::Vector3d& p : points) {
    if (!(in >> p.x() >> p.y() >> p.z())) return fail("truncated vertex list");
  }
  for (long f = 0; f < faces; ++f) {
    int count = 0;
    if (!(in >> count) || count < 3) return fail("bad face");
    PlyPolygon polygon;
    for (int k = 0; k < count; ++k) {
      long index = -1;
      if (!(in >> index) || index < 0 || index >= vertices) return fail("bad vertex index");
      polygon.vertices.push_back(points[static_cast<std::size_t>(index)]);
    }
    int red = 0, green = 0, blue = 0;
    if (!(in >> polygon.normal.x() >> polygon.normal.y() >> polygon.normal.z() >> red >> green >>
          blue)) {
      return fail("truncated face");
    }
    polygons.push_back(std::move(polygon));
  }
  return true;
}

std::string planesPlyPathFor(const std::string& map_path) {
  std::filesystem::path path(map_path);
  path.replace_extension(".planes.ply");
  return path.string();
}

}  // namespace slamd::planes
