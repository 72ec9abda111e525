#pragma once
// PlaneMap: the planes of keyframes fused into world planes that follow the back end's
// corrections (issue 23, item 5).
//
// Usage (one thread owns a PlaneMap, the mapping thread in the daemon; no threads inside):
//   planes::PlaneMap map(planes::PlaneMapParams{});  // throws std::invalid_argument on bad params
//   on each keyframe:  map.addKeyframe(id, T_world_camera, segmenter.segment(frame).planes);
//   on a correction:   map.setKeyframePoses(keyframe_poses);   // new T_world_camera per id
//                      map.forgetKeyframe(culled_id);           // keyframes the back end culled
//   reading:           for (const planes::WorldPlane& plane : map.worldPlanes()) use(plane);
//
// What is kept: per keyframe, its planes in its own camera frame (normal, offset, covariance,
// centroid, convex boundary) and its pose. The world planes are derived from them: they are
// rebuilt, lazily on the next read, whenever a keyframe is added, moved or forgotten, so they
// always agree with the newest poses (a keyframe has a few planes: rebuilding is cheap).
//
// Rebuild: keyframe planes are taken in keyframe order, each keyframe's largest first, and each
// joins the world plane it matches best, or starts a new one. A keyframe plane matches a world
// plane when
//  - their normals are within max_angle_deg (normals point to the side the surface was seen
//    from, so the two faces of a wall stay apart),
//  - the keyframe plane's centroid lies within max_distance_m of the world plane, and
//  - its boundary, cast onto the world plane, overlaps the world plane's polygon or lies within
//    max_gap_m of it (two parallel tables at one height stay two planes).
// The best match is the one with the least (angle / max_angle_deg)^2 + (distance /
// max_distance_m)^2. Afterwards, world planes that match each other by the same tests (a plane
// whose parts were first seen apart, then joined by a later keyframe) are merged.
// The gates are fixed distances, not a Mahalanobis test on the fits' covariances: a keyframe
// plane's covariance describes its depth noise only, while the pose error between keyframes and
// the fit's bias are larger and unmodelled, so a chi-square gate on the fit covariances would
// split planes that are one (docs/planes.md). The covariances weight the fusion instead.
//
// Fusion: around a reference normal n0 (the world plane's first member's) with tangents t1, t2,
// a plane not perpendicular to n0 is exactly n0.p + a t1.p + b t2.p + e = 0, linear in (a, b, e).
// Each member's (a, b, e) and its covariance (the fit's 4x4 covariance of (n, d), moved into the
// world frame by the keyframe's pose and mapped by the Jacobian, plus a floor of
// floor_angle_deg and floor_offset_m at the member's centroid for what the fit does not model)
// go into an information-weighted mean; the fused plane is (n0 + a t1 + b t2, e) normalised.
// The floor keeps one precise keyframe from outweighing the others when the errors between
// keyframes are larger than each one's noise.
//
// Frames: keyframe planes are in the camera optical frame (n.p + d = 0, plane_segmenter.hpp);
// T_world_camera maps camera points into the map frame; every WorldPlane field is in the map
// frame, metres.

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "slamd/common/se3.hpp"
#include "slamd/common/time.hpp"
#include "slamd/planes/plane_segmenter.hpp"

namespace slamd::planes {

struct PlaneMapParams {
  /// Largest angle between the normals of a keyframe plane and the world plane it joins,
  /// degrees. Range (0, 45].
  double max_angle_deg = 5.0;
  /// Largest distance of a keyframe plane's centroid from the world plane it joins, metres.
  /// Range (0, 1].
  double max_distance_m = 0.05;
  /// Largest gap, in the plane, between a keyframe plane's boundary and the world plane's
  /// polygon for them to join (0 = they must overlap), metres. Range [0, 10].
  double max_gap_m = 0.3;
  /// Uncertainty added to each member plane for the fusion (see the file comment): tilt,
  /// degrees, and offset at the member's centroid, metres. Range (0, 10] and (0, 1].
  double floor_angle_deg = 0.5;
  double floor_offset_m = 0.005;
  /// Keyframe planes smaller than this are not kept, m^2. Range [0, 100].
  double min_area_m2 = 0.0;

  /// Empty when valid, otherwise a sentence naming the first bad parameter.
  std::string validationError() const;
};

/// A plane of the map, fused from the planes of the keyframes that saw it.
struct WorldPlane {
  /// Stable across rebuilds while the plane keeps most of its members (a new id otherwise).
  std::int64_t id = 0;
  /// n.p + d = 0 in the map frame, |n| = 1, n towards the side the surface was seen from.
  Eigen::Vector3d normal_world = Eigen::Vector3d::UnitZ();
  double offset_m = 0.0;
  /// Convex hull, in the fused plane, of the members' boundaries cast onto it: a convex polygon
  /// in the map frame (metres, vertices on the plane, counter-clockwise seen from the side n
  /// points to). Convex, so it covers the gaps of an L-shaped floor or a wall with a door.
  std::vector<Eigen::Vector3d> polygon_world;
  double area_m2 = 0.0;  ///< of polygon_world
  /// Area-weighted mean of the members' centroids, cast onto the plane, metres.
  Eigen::Vector3d centroid_world = Eigen::Vector3d::Zero();
  /// Keyframes that saw it (ascending ids; a keyframe with two planes in it counts once).
  std::vector<std::int64_t> keyframe_ids;
  int members = 0;  ///< keyframe planes fused into it
};

/// The world planes at a moment, as published and exported.
struct PlaneMapSnapshot {
  Utime utime = 0;                 ///< capture time of the newest keyframe, microseconds
  std::string frame_id;            ///< the map frame
  std::vector<WorldPlane> planes;  ///< largest first
};

class PlaneMap {
 public:
  /// Throws std::invalid_argument when params.validationError() is not empty.
  explicit PlaneMap(const PlaneMapParams& params = PlaneMapParams());

  /// Keeps the planes of keyframe `keyframe_id` (camera frame, as PlaneSegmenter gives them;
  /// boundary_camera, centroid_camera, normal_camera, offset_m, covariance, area_m2 are used)
  /// at pose T_world_camera. An existing id is replaced. Planes with a non-finite field or fewer
  /// than 3 boundary vertices, and a non-finite pose, are ignored (counted in ignoredPlanes()).
  void addKeyframe(std::int64_t keyframe_id, const SE3& T_world_camera,
                   const std::vector<Plane>& planes_camera, Utime utime = 0);
  /// New poses (T_world_camera, map frame) of kept keyframes; ids not kept are ignored.
  /// Returns how many kept keyframes moved.
  std::size_t setKeyframePoses(const std::vector<std::pair<std::int64_t, SE3>>& keyframe_poses);
  /// Forgets a keyframe (culled by the back end); its planes leave the world planes.
  void forgetKeyframe(std::int64_t keyframe_id);
  void clear();

  /// The world planes from the newest poses (rebuilt first when anything changed), largest
  /// first.
  const std::vector<WorldPlane>& worldPlanes();
  /// worldPlanes() with the newest keyframe's time and the given frame name.
  PlaneMapSnapshot snapshot(const std::string& frame_id);

  std::vector<std::int64_t> keyframeIds() const;
  std::size_t keyframeCount() const { return keyframes_.size(); }
  std::size_t keyframePlaneCount() const;
  std::int64_t ignoredPlanes() const { return ignored_planes_; }
  /// Rebuilds done so far (each after a change, on the next read).
  std::int64_t rebuilds() const { return rebuilds_; }
  const PlaneMapParams& params() const { return params_; }

 private:
  /// A keyframe plane as kept (camera frame).
  struct KeptPlane {
    Eigen::Vector3d normal_camera;
    double offset_m;
    Eigen::Matrix4d covariance;
    Eigen::Vector3d centroid_camera;
    double area_m2;
    std::vector<Eigen::Vector3d> boundary_camera;
  };
  struct Keyframe {
    SE3 T_world_camera = SE3::Identity();
    Utime utime = 0;
    std::vector<KeptPlane> planes;
  };
  struct Member;
  struct Cluster;

  void rebuild();

  PlaneMapParams params_;
  std::map<std::int64_t, Keyframe> keyframes_;
  std::vector<WorldPlane> world_planes_;
  bool dirty_ = false;
  std::int64_t next_plane_id_ = 0;
  /// (keyframe id, plane index in it) -> world plane id of the last rebuild, for stable ids.
  std::map<std::pair<std::int64_t, int>, std::int64_t> previous_id_;
  std::int64_t ignored_planes_ = 0;
  std::int64_t rebuilds_ = 0;
};

/// Distance between the polygons of two world planes, measured in `a`'s plane with `b`'s polygon
/// cast onto it, metres; 0 when they overlap or touch (the extent test of the association).
double polygonGapM(const WorldPlane& a, const WorldPlane& b);

/// Depth with the noise across planes removed: each pixel labelled with a plane (labels of
/// `segmentation`, CV_32S) whose measured depth z lies within max_sigmas * sigma_z of the depth
/// z_p where its ray meets that plane (sigma_z = kinectSigmaZ(z_p)) gets z_p; other pixels keep
/// their measurement. The point z_p r (r the pixel's ray, r.z = 1) is where the ray meets the
/// plane, so the cloud built from the result has the plane's points on the plane. Rays within
/// about 3 degrees of the plane (|n.r| < 0.05 |r|) are left alone: there the meeting point is
/// ill-conditioned.
struct DepthSnapStats {
  std::int64_t labelled = 0;  ///< pixels with a plane label and a valid depth
  std::int64_t snapped = 0;   ///< of them, moved onto their plane
};

/// @param depth_m CV_32FC1 metres along z, NaN = none (the segmented frame's depth).
/// @param snapped_depth_m output, CV_32FC1 of the same size (reallocated only when needed).
/// Throws std::invalid_argument when the sizes or types of depth, labels and intrinsics differ,
/// or max_sigmas is not positive.
DepthSnapStats snapDepthToPlanes(const cv::Mat& depth_m, const PlaneSegmentation& segmentation,
                                 const CameraIntrinsics& intrinsics, double max_sigmas,
                                 cv::Mat& snapped_depth_m);

/// Writes the planes as an ASCII PLY of polygons: element vertex (float x y z, map frame,
/// metres), element face (list uchar int vertex_indices: one face per plane, its polygon in
/// order; float nx ny nz: the plane's normal; uchar red green blue: a colour per plane id), with
/// the frame and each plane's id, offset and area in comments. Crash-safe (writeOutputFile).
/// False with a sentence in *error when it cannot be written.
bool writePlaneMapPly(const std::string& path, const PlaneMapSnapshot& snapshot,
                      std::string* error = nullptr);

/// A polygon as read back from such a PLY.
struct PlyPolygon {
  std::vector<Eigen::Vector3d> vertices;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
};

/// Reads a PLY written by writePlaneMapPly (for tests and tools). False on anything else.
bool readPlaneMapPly(const std::string& path, std::vector<PlyPolygon>& polygons,
                     std::string* error = nullptr);

/// The sibling file of a map file for its planes: "dir/map.bt" -> "dir/map.planes.ply".
std::string planesPlyPathFor(const std::string& map_path);

}  // namespace slamd::planes
