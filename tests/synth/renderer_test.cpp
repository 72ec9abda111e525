#include "slamd/synth/renderer.hpp"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "slamd/synth/motion.hpp"
#include "synth_test_support.hpp"

namespace slamd::synth {
namespace {

const std::vector<std::string> kExact = {"synthetic.sensor.exact=true"};

/// One large wall at x = 3 m facing -x (towards a camera near the origin).
Scene singleWallScene() {
  Scene scene;
  scene.name = "wall";
  scene.textures.push_back(Texture::generate(TextureKind::kPlaster, 0.5, 1, 64));
  SurfaceRect wall;
  wall.origin_world = Eigen::Vector3d(3.0, 10.0, 10.0);
  wall.edge_u_world = Eigen::Vector3d(0.0, -20.0, 0.0);
  wall.edge_v_world = Eigen::Vector3d(0.0, 0.0, -20.0);
  scene.rects.push_back(wall);
  scene.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-10, -10, -10), Eigen::Vector3d(3, 10, 10));
  return scene;
}

TEST(Renderer, ExactDepthEqualsTheAnalyticRayPlaneDistance) {
  const Scene scene = singleWallScene();
  const CameraIntrinsics intrinsics;
  Renderer renderer(scene, intrinsics);
  SE3 T_world_camera = SE3::Identity();
  T_world_camera.linear() = lookRotation(0.35, 0.17, 0.09);
  T_world_camera.translation() = Eigen::Vector3d(0.4, -0.3, 0.2);
  RenderOutput out;
  renderer.render(T_world_camera, out);
  double worst = 0.0;
  for (int v = 0; v < intrinsics.height; ++v) {
    for (int u = 0; u < intrinsics.width; ++u) {
      // Ray with unit camera z: the hit parameter along it is the depth.
      const Eigen::Vector3d ray_world = T_world_camera.linear() * intrinsics.ray(u, v);
      const double analytic_z = (3.0 - T_world_camera.translation().x()) / ray_world.x();
      const double depth = out.depth_m.at<float>(v, u);
      ASSERT_TRUE(std::isfinite(depth)) << "pixel " << u << "," << v;
      worst = std::max(worst, std::abs(depth - analytic_z) / analytic_z);
    }
  }
  EXPECT_LT(worst, 2e-7);  // float rounding of a double-precision intersection
}

TEST(Renderer, RenderMatchesBruteForceRayCastingInEveryScene) {
  std::mt19937 rng(42);
  for (const std::string& name : sceneNames()) {
    const auto source = test::makeSyntheticSource(name, kExact);
    const Trajectory gt = *source->groundTruth();
    const CameraIntrinsics k = *source->intrinsics();
    RenderOutput out;
    int mismatches = 0;
    int checked = 0;
    for (int index : {0, source->frameCount() / 2, source->frameCount() - 1}) {
      source->renderExact(index, out);
      const SE3& T = gt[static_cast<std::size_t>(index)].T_world_camera;
      std::uniform_int_distribution<int> col(0, k.width - 1);
      std::uniform_int_distribution<int> row(0, k.height - 1);
      for (int sample = 0; sample < 1500; ++sample) {
        const int u = col(rng);
        const int v = row(rng);
        int id = -1;
        const double z =
            test::bruteForceRayCast(source->scene(), T.translation(), T.linear() * k.ray(u, v), id);
        const double depth = out.depth_m.at<float>(v, u);
        ++checked;
        if (!std::isfinite(z)) {
          if (std::isfinite(depth)) ++mismatches;
          continue;
        }
        if (!(std::abs(depth - z) <= 1e-6 * z)) {
          ++mismatches;
          ADD_FAILURE() << name << " frame " << index << " pixel " << u << "," << v << ": render "
                        << depth << " m (surface " << out.surface_id.at<int>(v, u)
                        << "), brute force " << z << " m (surface " << id << ")";
        }
      }
    }
    EXPECT_EQ(mismatches, 0) << name << ": " << checked << " pixels checked";
  }
}

TEST(Renderer, BackProjectedDepthLandsOnSceneSurfacesWithinOneMillimetre) {
  for (const std::string& name : sceneNames()) {
    const auto source = test::makeSyntheticSource(name, kExact);
    const Trajectory gt = *source->groundTruth();
    const CameraIntrinsics k = *source->intrinsics();
    const Scene& scene = source->scene();
    RenderOutput out;
    double worst_m = 0.0;
    int points = 0;
    for (int index : {0, source->frameCount() / 3, source->frameCount() - 1}) {
      source->renderExact(index, out);
      const SE3& T_world_camera = gt[static_cast<std::size_t>(index)].T_world_camera;
      for (int v = 0; v < k.height; v += 4) {
        for (int u = 0; u < k.width; u += 4) {
          const double depth = out.depth_m.at<float>(v, u);
          if (!std::isfinite(depth)) continue;
          const Eigen::Vector3d p_world = T_world_camera * k.backProject(u, v, depth);
          double nearest = std::numeric_limits<double>::infinity();
          for (const auto& rect : scene.rects) {
            nearest = std::min(nearest, rect.distanceTo(p_world));
            if (nearest < 1e-4) break;
          }
          worst_m = std::max(worst_m, nearest);
          ++points;
        }
      }
    }
    EXPECT_GT(points, 10000) << name;
    EXPECT_LT(worst_m, 1e-3) << name;
  }
}

TEST(Renderer, AClosedSceneLeavesNoPixelWithoutDepth) {
  for (const std::string& name : sceneNames()) {
    const auto source = test::makeSyntheticSource(name, kExact);
    RenderOutput out;
    for (int index = 0; index < source->frameCount(); index += source->frameCount() / 6) {
      source->renderExact(index, out);
      cv::Mat invalid = out.depth_m != out.depth_m;  // NaN compares unequal to itself
      EXPECT_EQ(cv::countNonZero(invalid), 0) << name << " frame " << index;
      double min_id = 0.0;
      cv::minMaxLoc(out.surface_id, &min_id);
      EXPECT_GE(min_id, 0.0) << name << " frame " << index;
    }
  }
}

TEST(Renderer, SurfacesSeenFromBehindAreInvisible) {
  const Scene scene = singleWallScene();
  Renderer renderer(scene, CameraIntrinsics());
  SE3 T_world_camera = SE3::Identity();
  T_world_camera.linear() = lookRotation(M_PI, 0.0, 0.0);  // behind the wall, looking back at it
  T_world_camera.translation() = Eigen::Vector3d(6.0, 0.0, 0.0);
  RenderOutput out;
  renderer.render(T_world_camera, out);
  EXPECT_EQ(cv::countNonZero(out.depth_m == out.depth_m), 0);
}

TEST(Renderer, ClipsSurfacesCrossingTheCameraPlane) {
  // The corridor floor and walls pass behind the camera; nothing behind may be drawn and the
  // floor must still cover the lower image exactly.
  const auto source = test::makeSyntheticSource("corridor", kExact);
  Renderer renderer(source->scene(), *source->intrinsics());
  SE3 T_world_camera = SE3::Identity();
  T_world_camera.linear() = lookRotation(0.0, -0.4, 0.0);
  T_world_camera.translation() = Eigen::Vector3d(15.0, 0.0, 1.2);
  RenderOutput out;
  renderer.render(T_world_camera, out);
  const CameraIntrinsics k = *source->intrinsics();
  const int v = k.height - 1;
  for (int u = 0; u < k.width; u += 16) {
    const Eigen::Vector3d ray_world = T_world_camera.linear() * k.ray(u, v);
    const double floor_z = -1.2 / ray_world.z();
    EXPECT_NEAR(out.depth_m.at<float>(v, u), floor_z, 1e-5 * floor_z) << "pixel " << u;
  }
}

}  // namespace
}  // namespace slamd::synth
