#include "slamd/planes/plane_map.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "planes_test_support.hpp"
#include "scoped_temp_dir.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/synth/synthetic_source.hpp"

namespace slamd::planes {
namespace {

SE3 pose(const Eigen::Vector3d& translation, double yaw_rad = 0.0) {
  SE3 T = SE3::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.translation() = translation;
  return T;
}

// ---------------------------------------------------------------------------------------------
// Hand-made planes: rectangles on known world planes, seen from known poses, exact.

/// The keyframe plane (camera frame) of the world rectangle with corners `corners_world`
/// (on the plane n.p + d = 0) seen from T_world_camera, with a covariance of a well-measured
/// plane (0.05 deg, 0.5 mm).
Plane cameraPlane(const Eigen::Vector3d& normal_world, double offset_world_m,
                  const std::vector<Eigen::Vector3d>& corners_world, const SE3& T_world_camera) {
  Plane plane;
  const Eigen::Matrix3d R = T_world_camera.linear();
  const Eigen::Vector3d t = T_world_camera.translation();
  plane.normal_camera = R.transpose() * normal_world;
  plane.offset_m = offset_world_m + normal_world.dot(t);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : corners_world) {
    plane.boundary_camera.push_back(T_world_camera.inverse() * p);
    sum += plane.boundary_camera.back();
  }
  plane.centroid_camera = sum / static_cast<double>(corners_world.size());
  const double tilt = 0.05 * kPi / 180.0;
  plane.covariance.diagonal() << tilt * tilt, tilt * tilt, tilt * tilt, 0.0005 * 0.0005;
  plane.area_m2 = 1.0;
  plane.inlier_pixels = 10000;
  return plane;
}

/// The wall x = 3 m (normal -x, towards the origin), the part y in [y0, y1], z in [0, 2].
Plane wallPart(double y0, double y1, const SE3& T_world_camera, double x_m = 3.0) {
  const Eigen::Vector3d n(-1.0, 0.0, 0.0);
  return cameraPlane(n, x_m, {{x_m, y0, 0.0}, {x_m, y1, 0.0}, {x_m, y1, 2.0}, {x_m, y0, 2.0}},
                     T_world_camera);
}

/// The floor z = 0 (normal +z), the part x in [0, 2], y in [y0, y1].
Plane floorPart(double y0, double y1, const SE3& T_world_camera) {
  return cameraPlane({0.0, 0.0, 1.0}, 0.0,
                     {{0.0, y0, 0.0}, {2.0, y0, 0.0}, {2.0, y1, 0.0}, {0.0, y1, 0.0}},
                     T_world_camera);
}

TEST(PlaneMap, OverlappingPartsOfAWallSeenFromTwoKeyframesBecomeOneWorldPlane) {
  PlaneMap map;
  const SE3 first = pose({0.0, 0.0, 1.0}, 0.3);
  const SE3 second = pose({0.5, 1.5, 1.0}, -0.2);
  map.addKeyframe(1, first, {wallPart(0.0, 2.0, first), floorPart(0.0, 2.0, first)});
  map.addKeyframe(2, second, {wallPart(1.0, 3.0, second)});
  const std::vector<WorldPlane>& planes = map.worldPlanes();
  ASSERT_EQ(planes.size(), 2u);
  const WorldPlane& wall = planes[0];  // largest first: 3 x 2 m against the floor's 2 x 2 m
  EXPECT_LT(angleDeg(wall.normal_world, {-1.0, 0.0, 0.0}), 1e-6);
  EXPECT_NEAR(wall.offset_m, 3.0, 1e-9);
  EXPECT_EQ(wall.keyframe_ids, (std::vector<std::int64_t>{1, 2}));
  EXPECT_EQ(wall.members, 2);
  // The hull of the union: y in [0, 3], z in [0, 2].
  EXPECT_NEAR(wall.area_m2, 6.0, 1e-4);
  ASSERT_EQ(wall.polygon_world.size(), 4u);
  for (const Eigen::Vector3d& p : wall.polygon_world) {
    EXPECT_NEAR(p.x(), 3.0, 1e-5);
    EXPECT_TRUE(std::abs(p.y()) < 1e-5 || std::abs(p.y() - 3.0) < 1e-5) << p.transpose();
  }
  // Counter-clockwise seen from the side the normal points to.
  const Eigen::Vector3d turn = (wall.polygon_world[1] - wall.polygon_world[0])
                                   .cross(wall.polygon_world[2] - wall.polygon_world[1]);
  EXPECT_GT(turn.dot(wall.normal_world), 0.0);
  EXPECT_NEAR(planes[1].area_m2, 4.0, 1e-4);
  EXPECT_EQ(planes[1].keyframe_ids, (std::vector<std::int64_t>{1}));
}

TEST(PlaneMap, PartsApartBeyondTheGapStayTwoPlanesUntilAKeyframeSeesWhatJoinsThem) {
  PlaneMapParams params;
  params.max_gap_m = 0.3;
  PlaneMap map(params);
  const SE3 T = pose({0.0, 0.0, 1.0});
  map.addKeyframe(1, T, {wallPart(0.0, 1.0, T)});
  map.addKeyframe(2, T, {wallPart(2.0, 3.0, T)});
  EXPECT_EQ(map.worldPlanes().size(), 2u);
  // Within the gap: one plane.
  map.addKeyframe(3, T, {wallPart(1.2, 1.8, T)});
  ASSERT_EQ(map.worldPlanes().size(), 1u);
  EXPECT_EQ(map.worldPlanes()[0].keyframe_ids.size(), 3u);
}

TEST(PlaneMap, ParallelPlanesTenCentimetresApartStayApart) {
  PlaneMap map;
  const SE3 T = pose({0.0, 0.0, 1.0});
  map.addKeyframe(1, T, {wallPart(0.0, 2.0, T, 3.0)});
  map.addKeyframe(2, T, {wallPart(0.0, 2.0, T, 3.1)});
  ASSERT_EQ(map.worldPlanes().size(), 2u);
  // Nor do the two faces of one wall (opposite normals) merge.
  PlaneMap faces;
  Plane back = wallPart(0.0, 2.0, T);
  back.normal_camera = -back.normal_camera;
  back.offset_m = -back.offset_m;
  faces.addKeyframe(1, T, {wallPart(0.0, 2.0, T), back});
  EXPECT_EQ(faces.worldPlanes().size(), 2u);
}

TEST(PlaneMap, ACorrectionThatMovesAKeyframeMovesItsPlanes) {
  PlaneMap map;
  const SE3 first = pose({0.0, 0.0, 1.0});
  const SE3 second = pose({0.0, 1.0, 1.0});
  map.addKeyframe(1, first, {wallPart(0.0, 2.0, first)});
  map.addKeyframe(2, second, {wallPart(1.0, 3.0, second)});
  ASSERT_EQ(map.worldPlanes().size(), 1u);
  const std::int64_t id = map.worldPlanes()[0].id;

  // The back end moves keyframe 2 by 20 cm along x: the wall it saw 3 m ahead is now at
  // x = 3.2 m, apart from keyframe 1's.
  const SE3 moved = pose({0.2, 1.0, 1.0});
  EXPECT_EQ(map.setKeyframePoses({{1, first}, {2, moved}}), 1u);
  const std::vector<WorldPlane> planes = map.worldPlanes();
  ASSERT_EQ(planes.size(), 2u);
  std::map<std::int64_t, double> offset_of_keyframe;
  for (const WorldPlane& plane : planes) {
    ASSERT_EQ(plane.keyframe_ids.size(), 1u);
    offset_of_keyframe[plane.keyframe_ids[0]] = plane.offset_m;
  }
  EXPECT_NEAR(offset_of_keyframe[1], 3.0, 1e-9);
  EXPECT_NEAR(offset_of_keyframe[2], 3.2, 1e-9);
  // Moved back: one plane again, with the id it had (most of its members kept it).
  map.setKeyframePoses({{2, second}});
  ASSERT_EQ(map.worldPlanes().size(), 1u);
  EXPECT_EQ(map.worldPlanes()[0].id, id);
  EXPECT_EQ(map.rebuilds(), 3);
}

TEST(PlaneMap, AForgottenKeyframeLeavesTheWorldPlanes) {
  PlaneMap map;
  const SE3 T = pose({0.0, 0.0, 1.0});
  map.addKeyframe(1, T, {wallPart(0.0, 2.0, T), floorPart(0.0, 2.0, T)});
  map.addKeyframe(2, T, {wallPart(1.0, 3.0, T)});
  ASSERT_EQ(map.worldPlanes().size(), 2u);
  map.forgetKeyframe(1);
  const std::vector<WorldPlane>& planes = map.worldPlanes();
  ASSERT_EQ(planes.size(), 1u);  // the floor was only keyframe 1's
  EXPECT_EQ(planes[0].keyframe_ids, (std::vector<std::int64_t>{2}));
  EXPECT_NEAR(planes[0].area_m2, 4.0, 1e-4);
  EXPECT_EQ(map.keyframeIds(), (std::vector<std::int64_t>{2}));
  map.clear();
  EXPECT_TRUE(map.worldPlanes().empty());
}

TEST(PlaneMap, FusionWeighsTheBetterMeasuredPlaneMore) {
  PlaneMapParams params;
  params.floor_offset_m = 1e-4;  // small, so that the planes' own covariances decide
  params.floor_angle_deg = 0.01;
  PlaneMap map(params);
  const SE3 T = pose({0.0, 0.0, 1.0});
  Plane precise = wallPart(0.0, 2.0, T, 3.0);
  Plane noisy = wallPart(0.0, 2.0, T, 3.02);
  noisy.covariance *= 100.0;  // ten times the standard deviation
  map.addKeyframe(1, T, {precise});
  map.addKeyframe(2, T, {noisy});
  ASSERT_EQ(map.worldPlanes().size(), 1u);
  // Information weights 100 : 1 -> 3.0 + 0.02 / 101.
  EXPECT_NEAR(map.worldPlanes()[0].offset_m, 3.0 + 0.02 / 101.0, 2e-4);
}

TEST(PlaneMap, IgnoresNonFinitePlanesAndPosesAndRejectsBadParameters) {
  PlaneMap map;
  const SE3 T = pose({0.0, 0.0, 1.0});
  Plane bad = wallPart(0.0, 2.0, T);
  bad.offset_m = std::numeric_limits<double>::quiet_NaN();
  Plane few = wallPart(0.0, 2.0, T);
  few.boundary_camera.resize(2);
  map.addKeyframe(1, T, {bad, few, wallPart(0.0, 2.0, T)});
  EXPECT_EQ(map.ignoredPlanes(), 2);
  EXPECT_EQ(map.worldPlanes().size(), 1u);
  SE3 nan_pose = T;
  nan_pose.translation().x() = std::numeric_limits<double>::quiet_NaN();
  map.addKeyframe(2, nan_pose, {wallPart(0.0, 2.0, T)});
  EXPECT_EQ(map.ignoredPlanes(), 3);
  EXPECT_EQ(map.keyframeCount(), 1u);

  PlaneMapParams params;
  params.max_angle_deg = 0.0;
  EXPECT_THROW(PlaneMap{params}, std::invalid_argument);
  params = PlaneMapParams();
  params.max_gap_m = -1.0;
  EXPECT_THROW(PlaneMap{params}, std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Rendered scenes: slamd's synthetic room, keyframes along its trajectory at their true poses.

/// Structural surfaces in how many keyframes each covers >= 8% of the image within the
/// segmenter's range; then the world planes on each.
void checkRoomPlanes(bool exact, double max_normal_error_deg, double max_offset_error_m) {
  const auto source = makeSource("room", exact);
  const Trajectory gt = *source->groundTruth();
  const synth::Scene& scene = source->scene();
  PlaneSegmenter segmenter;
  PlaneMap map;
  synth::RenderOutput truth;
  std::map<int, int> keyframes_seeing;  // structural surface -> keyframes
  const int keyframes = 24;
  const int frames = source->frameCount();
  for (int k = 0; k < keyframes; ++k) {
    const int index = k * (frames - 1) / (keyframes - 1);
    const RgbdFramePtr frame = source->renderFrame(index);
    const SE3& T_world_camera = gt[static_cast<std::size_t>(index)].T_world_camera;
    map.addKeyframe(k, T_world_camera, segmenter.segment(*frame).planes, frame->utime);
    source->renderExact(index, truth);
    std::map<int, int> pixels;
    for (int v = 0; v < truth.surface_id.rows; ++v) {
      for (int u = 0; u < truth.surface_id.cols; ++u) {
        const int surface = truth.surface_id.at<int>(v, u);
        if (surface >= 0 && truth.depth_m.at<float>(v, u) <= 4.5f) ++pixels[surface];
      }
    }
    for (const auto& [surface, count] : pixels) {
      const synth::SurfaceRect& rect = scene.rects[static_cast<std::size_t>(surface)];
      if (rect.edge_u_world.cross(rect.edge_v_world).norm() < kMinStructuralAreaM2) continue;
      if (count >= 0.08 * static_cast<double>(truth.surface_id.total()))
        ++keyframes_seeing[surface];
    }
  }
  const auto rebuild_start = std::chrono::steady_clock::now();
  const std::vector<WorldPlane>& planes = map.worldPlanes();
  const double rebuild_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - rebuild_start)
          .count();
  int checked = 0, single = 0;
  double worst_normal = 0.0, worst_offset = 0.0;
  for (const auto& [surface, seen] : keyframes_seeing) {
    if (seen < 2) continue;
    const synth::SurfaceRect& rect = scene.rects[static_cast<std::size_t>(surface)];
    const Eigen::Vector3d normal = rect.normal();
    const double offset = -normal.dot(rect.origin_world);
    // Every world plane of some size on this surface's plane, by the map's own gates (a door
    // 12 mm proud of its wall and fitted at a tilt is another plane, as it should be).
    std::vector<const WorldPlane*> near;
    for (const WorldPlane& plane : planes) {
      if (plane.area_m2 < 0.5) continue;
      if (angleDeg(plane.normal_world, normal) < map.params().max_angle_deg &&
          std::abs(plane.offset_m - offset) < map.params().max_distance_m) {
        near.push_back(&plane);
      }
    }
    ASSERT_GE(near.size(), 1u) << "surface " << surface << " has no world plane";
    ++checked;
    if (near.size() == 1) ++single;
    std::size_t most_keyframes = 0;
    for (const WorldPlane* plane : near) {
      const double normal_error = angleDeg(plane->normal_world, normal);
      const double offset_error = std::abs(plane->offset_m - offset);
      worst_normal = std::max(worst_normal, normal_error);
      worst_offset = std::max(worst_offset, offset_error);
      EXPECT_LT(normal_error, max_normal_error_deg) << "surface " << surface;
      EXPECT_LT(offset_error, max_offset_error_m) << "surface " << surface;
      most_keyframes = std::max(most_keyframes, plane->keyframe_ids.size());
      // Parts of one surface stay apart only where no keyframe saw what joins them.
      for (const WorldPlane* other : near) {
        if (other == plane) continue;
        EXPECT_GT(polygonGapM(*plane, *other), map.params().max_gap_m)
            << "surface " << surface << ": planes " << plane->id << " and " << other->id
            << " should have merged";
      }
    }
    // Merged across keyframes: a part is seen by several.
    EXPECT_GE(most_keyframes, 2u) << "surface " << surface;
    // The walls (vertical) are seen whole from the room's middle: one plane each.
    if (std::abs(normal.z()) < 0.1) {
      EXPECT_EQ(near.size(), 1u) << "wall " << surface << " is " << near.size() << " planes";
    }
  }
  EXPECT_GE(checked, 5);
  std::printf(
      "[ stats    ] room %s, %d keyframes: %zu world planes from %zu keyframe planes; of %d "
      "structural surfaces seen by >= 2 keyframes, %d are one world plane; worst normal error "
      "%.3f deg, worst offset error %.2f mm; rebuilt in %.1f ms\n",
      exact ? "exact" : "noisy", keyframes, planes.size(), map.keyframePlaneCount(), checked,
      single, worst_normal, worst_offset * 1e3, rebuild_ms);
}

TEST(PlaneMap, RecoversTheRenderedRoomsWallsAsOneWorldPlaneEachAndOtherSurfacesInTheirSeenParts) {
  checkRoomPlanes(true, 0.5, 0.01);
  checkRoomPlanes(false, 1.0, 0.02);
}

TEST(SnapDepthToPlanes, BringsKinectModelPointsOnRenderedSurfacesCloserToTheirTruePlanes) {
  const auto source = makeSource("room", false);
  const Trajectory gt = *source->groundTruth();
  const synth::Scene& scene = source->scene();
  PlaneSegmenter segmenter;
  synth::RenderOutput truth;
  double before_sum = 0.0, after_sum = 0.0;
  std::int64_t points = 0, labelled = 0, snapped = 0;
  double snap_ms = 0.0;  // the slowest frame's
  for (const int index : {10, 60, 110}) {
    const RgbdFramePtr frame = source->renderFrame(index);
    source->renderExact(index, truth);
    const PlaneSegmentation& segmentation = segmenter.segment(*frame);
    cv::Mat snapped_depth;
    const auto snap_start = std::chrono::steady_clock::now();
    const DepthSnapStats stats =
        snapDepthToPlanes(frame->depth_m, segmentation, frame->intrinsics, 3.0, snapped_depth);
    snap_ms = std::max(snap_ms, std::chrono::duration<double, std::milli>(
                                    std::chrono::steady_clock::now() - snap_start)
                                    .count());
    labelled += stats.labelled;
    snapped += stats.snapped;
    const SE3 T_camera_world = gt[static_cast<std::size_t>(index)].T_world_camera.inverse();
    // Distance to the true surface plane of every labelled pixel on a structural surface.
    for (int v = 0; v < truth.surface_id.rows; ++v) {
      for (int u = 0; u < truth.surface_id.cols; ++u) {
        const int surface = truth.surface_id.at<int>(v, u);
        const float z = frame->depth_m.at<float>(v, u);
        if (surface < 0 || !(z > 0.0f) || segmentation.labels.at<int>(v, u) < 0) continue;
        const synth::SurfaceRect& rect = scene.rects[static_cast<std::size_t>(surface)];
        if (rect.edge_u_world.cross(rect.edge_v_world).norm() < kMinStructuralAreaM2) continue;
        const Eigen::Vector3d n = T_camera_world.linear() * rect.normal();
        const double d = -n.dot(T_camera_world * rect.origin_world);
        const Eigen::Vector3d ray = frame->intrinsics.ray(u, v);
        const double before = n.dot(ray * z) + d;
        const double after = n.dot(ray * snapped_depth.at<float>(v, u)) + d;
        before_sum += before * before;
        after_sum += after * after;
        ++points;
      }
    }
  }
  ASSERT_GT(points, 100000);
  const double rms_before = std::sqrt(before_sum / static_cast<double>(points));
  const double rms_after = std::sqrt(after_sum / static_cast<double>(points));
  std::printf(
      "[ stats    ] room, Kinect model, 3 frames: %lld points on structural surfaces, distance "
      "to the true plane RMS %.2f mm measured, %.2f mm snapped; %.1f%% of labelled pixels "
      "snapped, in %.2f ms per 640x480 frame at most\n",
      static_cast<long long>(points), rms_before * 1e3, rms_after * 1e3,
      100.0 * static_cast<double>(snapped) / static_cast<double>(labelled), snap_ms);
  EXPECT_LT(rms_after, 0.5 * rms_before);
  EXPECT_GT(snapped, labelled / 2);
}

TEST(SnapDepthToPlanes, KeepsPointsBeyondTheNoiseBoundAndRejectsMismatchedInputs) {
  CameraIntrinsics k;
  k.fx = k.fy = 100.0;
  k.cx = 1.5;
  k.cy = 1.5;
  k.width = 4;
  k.height = 4;
  PlaneSegmentation segmentation;
  segmentation.labels = cv::Mat(4, 4, CV_32SC1, cv::Scalar(0));
  segmentation.labels.at<int>(0, 0) = -1;
  Plane wall;  // z = 2 m
  wall.normal_camera = {0.0, 0.0, -1.0};
  wall.offset_m = 2.0;
  segmentation.planes.push_back(wall);
  cv::Mat depth(4, 4, CV_32FC1, cv::Scalar(2.003f));  // 0.6 sigma at 2 m (4.8 mm)
  depth.at<float>(0, 0) = 2.003f;                     // no label: kept
  depth.at<float>(1, 1) = 2.1f;                       // 20 sigma off: kept
  depth.at<float>(2, 2) = std::numeric_limits<float>::quiet_NaN();
  cv::Mat snapped;
  const DepthSnapStats stats = snapDepthToPlanes(depth, segmentation, k, 3.0, snapped);
  EXPECT_EQ(stats.labelled, 14);
  EXPECT_EQ(stats.snapped, 13);
  EXPECT_FLOAT_EQ(snapped.at<float>(0, 0), 2.003f);
  EXPECT_FLOAT_EQ(snapped.at<float>(1, 1), 2.1f);
  EXPECT_FLOAT_EQ(snapped.at<float>(3, 3), 2.0f);
  EXPECT_TRUE(std::isnan(snapped.at<float>(2, 2)));
  EXPECT_THROW(snapDepthToPlanes(depth(cv::Rect(0, 0, 3, 3)), segmentation, k, 3.0, snapped),
               std::invalid_argument);
  EXPECT_THROW(snapDepthToPlanes(depth, segmentation, k, 0.0, snapped), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// PLY export.

TEST(PlaneMapPly, WritesPolygonsThatReadBackWithTheirVerticesAndNormals) {
  PlaneMap map;
  const SE3 T = pose({0.0, 0.0, 1.0});
  map.addKeyframe(1, T, {wallPart(0.0, 2.0, T), floorPart(0.0, 3.0, T)}, 1'600'000'000'000'000);
  const PlaneMapSnapshot snapshot = map.snapshot("world");
  ASSERT_EQ(snapshot.planes.size(), 2u);
  EXPECT_EQ(snapshot.utime, 1'600'000'000'000'000);
  const test::ScopedTempDir dir("plane-map-ply");
  const std::string path = planesPlyPathFor((dir.path() / "map.bt").string());
  EXPECT_EQ(path, (dir.path() / "map.planes.ply").string());
  std::string error;
  ASSERT_TRUE(writePlaneMapPly(path, snapshot, &error)) << error;
  std::vector<PlyPolygon> polygons;
  ASSERT_TRUE(readPlaneMapPly(path, polygons, &error)) << error;
  ASSERT_EQ(polygons.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const WorldPlane& plane = snapshot.planes[i];
    ASSERT_EQ(polygons[i].vertices.size(), plane.polygon_world.size());
    EXPECT_LT((polygons[i].normal - plane.normal_world).norm(), 1e-6);
    for (std::size_t v = 0; v < plane.polygon_world.size(); ++v) {
      EXPECT_LT((polygons[i].vertices[v] - plane.polygon_world[v]).norm(), 1e-5);
    }
  }
  // The floor (6 m^2, first) has the corner (2, 3, 0).
  bool corner = false;
  for (const Eigen::Vector3d& p : polygons[0].vertices) {
    corner = corner || (p - Eigen::Vector3d(2.0, 3.0, 0.0)).norm() < 1e-5;
  }
  EXPECT_TRUE(corner);
  // Not a plane map PLY: refused with a reason.
  EXPECT_FALSE(readPlaneMapPly((dir.path() / "missing.ply").string(), polygons, &error));
  EXPECT_FALSE(error.empty());
  // An unwritable path fails with a sentence, not silently.
  EXPECT_FALSE(
      writePlaneMapPly((dir.path() / "no" / "such" / "dir.ply").string(), snapshot, &error));
}

}  // namespace
}  // namespace slamd::planes
