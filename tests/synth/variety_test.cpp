// The evaluation worlds' variety: regular tilings, gloss, lamps, look-around walks and the seeded
// draw that combines them (synth/variety.hpp).
#include "slamd/synth/variety.hpp"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

#include "slamd/synth/renderer.hpp"
#include "slamd/synth/texture.hpp"
#include "synth_test_support.hpp"

namespace slamd::synth {
namespace {

double luma(const cv::Vec3f& bgr) { return static_cast<double>(bgr[0] + bgr[1] + bgr[2]) / 3.0; }

TEST(TileTexture, IdenticalTilesRepeatExactlyAndAlternateByTheContrast) {
  TileStyle style;
  style.tiles_per_side = 8;
  style.contrast = 0.4;
  style.variation = 0.0;
  const Texture texture = Texture::tiles(style, 7, 128);
  const int tile = 128 / 8;
  // Tile (0, 0) and tile (2, 0) are the same pixels: the pattern repeats every two tiles.
  const cv::Mat& image = texture.level(0);
  EXPECT_EQ(cv::norm(image(cv::Rect(0, 0, tile, tile)), image(cv::Rect(2 * tile, 0, tile, tile)),
                     cv::NORM_INF),
            0.0);
  // Neighbouring tiles differ by the checker step: 0.4 * 255 grey levels.
  const double a = luma(texture.sample(tile / 2.0, tile / 2.0, 0, true));
  const double b = luma(texture.sample(1.5 * tile, tile / 2.0, 0, true));
  EXPECT_NEAR(std::abs(a - b), 0.4 * 255.0, 3.0);
}

TEST(TileTexture, VariationMakesTilesDifferAndBadStylesAreRefused) {
  TileStyle style;
  style.tiles_per_side = 8;
  style.contrast = 0.0;
  style.variation = 1.0;
  const Texture texture = Texture::tiles(style, 7, 128);
  std::set<int> shades;
  for (int k = 0; k < 8; ++k)
    shades.insert(static_cast<int>(luma(texture.sample(8 + 16 * k, 8, 0, true))));
  EXPECT_GE(shades.size(), 4u);

  style.tiles_per_side = 7;  // does not divide 128
  EXPECT_THROW(Texture::tiles(style, 1, 128), std::invalid_argument);
  style.tiles_per_side = 8;
  style.contrast = 1.5;
  EXPECT_THROW(Texture::tiles(style, 1, 128), std::invalid_argument);
}

TEST(SceneVariety, RegularFloorTilesHaveTheConfiguredPeriod) {
  SceneParams params;
  params.floor_tile_m = 0.5;
  const Scene scene = makeCorridor(params, 3);
  // The floor is the rectangle facing up at z = 0.
  const SurfaceRect* floor = nullptr;
  for (const auto& rect : scene.rects) {
    if (rect.normal().z() > 0.99 && std::abs(rect.origin_world.z()) < 1e-9) floor = &rect;
  }
  ASSERT_NE(floor, nullptr);
  const Texture& texture = scene.textures[static_cast<std::size_t>(floor->texture)];
  // 16 tiles per texture side: one tile spans size / 16 texels = 0.5 m.
  EXPECT_NEAR(texture.size() / 16.0 / floor->texels_per_m_u, 0.5, 1e-12);
}

TEST(SceneVariety, TheNewFeaturesLeaveTheRestOfTheSceneInPlace) {
  // Gloss, lamps, a tiled floor and a dado draw from their own stream: the layout (doors,
  // posters, their textures' offsets) is the same with and without them.
  SceneParams params;
  const Scene classic = makeCorridor(params, 11);
  params.wall_tile_height_m = 1.2;
  params.floor_tile_m = 0.4;
  params.gloss = 0.5;
  params.lamp_spacing_m = 3.0;
  const Scene varied = makeCorridor(params, 11);
  ASSERT_EQ(varied.rects.size(), classic.rects.size() + 2);  // one dado band per long wall
  std::size_t dado_bands = 0;
  std::size_t matched = 0;
  for (const auto& rect : varied.rects) {
    if (std::abs(rect.edge_v_world.norm() - 1.2) < 1e-9) ++dado_bands;
    if (rect.normal().z() > 0.99 && std::abs(rect.origin_world.z()) < 1e-9) continue;  // floor
    for (const auto& old : classic.rects) {
      if ((rect.origin_world - old.origin_world).norm() < 1e-12 &&
          (rect.texel_offset - old.texel_offset).norm() < 1e-12) {
        ++matched;
        break;
      }
    }
  }
  EXPECT_EQ(dado_bands, 2u);
  EXPECT_EQ(matched, classic.rects.size() - 1);  // all but the floor, whose tiles changed
  for (const auto& rect : classic.rects) EXPECT_EQ(rect.gloss, 0.0);
  EXPECT_EQ(classic.lamps.spacing_m, 0.0);
  EXPECT_EQ(varied.lamps.spacing_m, 3.0);
}

/// Mean luma of a patch of the rendered colour image around pixel (u, v).
double patchLuma(const RenderOutput& out, int u, int v) {
  const cv::Scalar mean = cv::mean(out.color_bgr(cv::Rect(u - 4, v - 4, 9, 9)));
  return (mean[0] + mean[1] + mean[2]) / 3.0;
}

/// Luma of the colour image at the pixel where the world point appears from T_world_camera.
double lumaAtWorldPoint(const Renderer& renderer, const SE3& T_world_camera,
                        const Eigen::Vector3d& p_world) {
  RenderOutput out;
  renderer.render(T_world_camera, out);
  const Eigen::Vector3d p = T_world_camera.inverse() * p_world;
  const Eigen::Vector2d uv = renderer.intrinsics().project(p);
  return patchLuma(out, static_cast<int>(std::lround(uv.x())),
                   static_cast<int>(std::lround(uv.y())));
}

SE3 cameraAt(const Eigen::Vector3d& position_world, double yaw_rad, double pitch_rad) {
  SE3 T_world_camera = SE3::Identity();
  T_world_camera.linear() = lookRotation(yaw_rad, pitch_rad, 0.0);
  T_world_camera.translation() = position_world;
  return T_world_camera;
}

TEST(RendererLighting, LampsMakePoolsOfLightAlongTheCorridorFloor) {
  SceneParams params;
  params.lamp_spacing_m = 3.0;  // lamps at x = 1.5 + 3 k
  params.lamp_strength = 0.8;
  params.doors = params.posters = false;
  const Scene lit = makeCorridor(params, 5);
  params.lamp_spacing_m = 0.0;
  const Scene even = makeCorridor(params, 5);
  const CameraIntrinsics intrinsics;
  const Renderer lit_renderer(lit, intrinsics);
  const Renderer even_renderer(even, intrinsics);
  // The floor seen straight down from 1 m, under a lamp and halfway between two lamps; dividing
  // by the evenly lit render cancels the floor's texture.
  const auto light = [&](double x_m) {
    const SE3 T = cameraAt({x_m, 0.0, 1.0}, 0.0, -M_PI / 2.0 + 1e-3);
    const Eigen::Vector3d floor_point(x_m, 0.0, 0.0);
    return lumaAtWorldPoint(lit_renderer, T, floor_point) /
           lumaAtWorldPoint(even_renderer, T, floor_point);
  };
  const double under = light(7.5);
  const double between = light(9.0);
  EXPECT_GT(under, 1.3 * between) << "under a lamp " << under << ", between lamps " << between;
}

TEST(RendererLighting, GlossAddsAHighlightThatMovesWithTheViewpoint) {
  SceneParams params;
  params.texture_density = 0.0;
  params.doors = params.posters = false;
  params.lamp_spacing_m = 3.0;  // lamps at x = 1.5 + 3 k, 2.55 m high
  params.lamp_strength = 0.5;
  params.gloss = 0.8;
  const Scene glossy = makeCorridor(params, 5);
  params.gloss = 0.0;
  const Scene matte = makeCorridor(params, 5);
  const CameraIntrinsics intrinsics;
  // A point of the +y wall (y = 1) under a lamp, seen from below (where the lamp's mirror image
  // is) and from above: matte paint looks the same from both (Lambert), gloss does not.
  const Eigen::Vector3d wall_point(10.5, 1.0, 2.0);
  const SE3 from_below = cameraAt({10.5, -0.5, 1.5}, M_PI / 2.0, std::atan2(0.5, 1.5));
  const SE3 from_above = cameraAt({10.5, -0.5, 2.45}, M_PI / 2.0, -std::atan2(0.45, 1.5));
  const auto change = [&](const Scene& scene) {
    const Renderer renderer(scene, intrinsics);
    return lumaAtWorldPoint(renderer, from_below, wall_point) -
           lumaAtWorldPoint(renderer, from_above, wall_point);
  };
  EXPECT_LT(std::abs(change(matte)), 2.0);
  EXPECT_GT(change(glossy), 20.0);
}

TEST(MotionVariety, LookAroundAddsAYawOscillation) {
  const Scene scene = makeCorridor(SceneParams(), 1);
  MotionParams params;
  const CameraMotion ahead(scene, MotionKind::kZigzag, params, 9);
  params.look_around_deg = 20.0;
  params.look_around_hz = 0.25;
  const CameraMotion looking(scene, MotionKind::kZigzag, params, 9);
  // At t = 1 s the oscillation sin(2 pi 0.25 t) is at its peak: 20 degrees of extra yaw.
  const Eigen::Matrix3d relative =
      ahead.poseAt(1.0).linear().transpose() * looking.poseAt(1.0).linear();
  const double angle_deg = Eigen::AngleAxisd(relative).angle() * 180.0 / M_PI;
  EXPECT_NEAR(angle_deg, 20.0, 0.5);
  EXPECT_EQ(ahead.poseAt(1.0).translation(), looking.poseAt(1.0).translation());
}

TEST(Variety, TheSameSeedDrawsTheSameWorldAndOthersDiffer) {
  std::set<std::string> draws;
  for (std::uint64_t seed : {1001, 1002, 1003, 2001, 2002, 2003}) {
    SceneParams scene_a;
    MotionParams motion_a;
    SensorParams sensor_a;
    SceneParams scene_b;
    MotionParams motion_b;
    SensorParams sensor_b;
    const std::string a = applyVariety(seed, scene_a, motion_a, sensor_a);
    const std::string b = applyVariety(seed, scene_b, motion_b, sensor_b);
    EXPECT_EQ(a, b);
    draws.insert(a);
    EXPECT_GE(scene_a.corridor_width_m, 1.6);
    EXPECT_LE(scene_a.corridor_width_m, 3.0);
    EXPECT_GE(motion_a.walk_speed_mps, 0.6);
    EXPECT_LE(motion_a.walk_speed_mps, 1.0);
    EXPECT_LE(sensor_a.exposure_variation, 0.3);
  }
  EXPECT_EQ(draws.size(), 6u);
}

TEST(Variety, ExactSensorsStayExact) {
  SceneParams scene;
  MotionParams motion;
  SensorParams sensor;
  sensor.exact_mode = true;
  for (std::uint64_t seed = 1; seed < 20; ++seed) {
    applyVariety(seed, scene, motion, sensor);
    EXPECT_EQ(sensor.exposure_variation, 0.0);
  }
}

TEST(Variety, TheSyntheticSourceDrawsFromItsSeedAndSaysWhat) {
  const auto source = test::makeSyntheticSource(
      "corridor", {"synthetic.variety=true", "synthetic.seed=2001", "synthetic.frames=3"});
  SceneParams scene;
  MotionParams motion;
  SensorParams sensor = source->config().sensor;
  const std::string expected = applyVariety(2001, scene, motion, sensor);
  EXPECT_NE(source->description().find("variety: " + expected), std::string::npos)
      << source->description();
  EXPECT_EQ(source->config().scene.corridor_width_m, scene.corridor_width_m);
  EXPECT_NE(source->renderFrame(2), nullptr);
}

}  // namespace
}  // namespace slamd::synth
