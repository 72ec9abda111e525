#include "slamd/synth/scene.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "random.hpp"
#include "slamd/common/config.hpp"

namespace slamd::synth {
namespace {

constexpr double kWallTexelM = 0.02;  ///< wall, floor and ceiling texture resolution (2 cm)
constexpr int kTilesPerTexture = 16;  ///< tiles along a side of a regular tiling's texture

/// Builds a scene piece by piece; every random choice comes from one seeded stream, in a fixed
/// order, so the scene depends only on (name, params, seed).
class SceneBuilder {
 public:
  SceneBuilder(const std::string& name, const SceneParams& params, std::uint64_t seed)
      : params_(params),
        rng_(deriveSeed(seed, 0x5CE4E, 0)),
        variety_rng_(deriveSeed(seed, 0x5CE4E, 1)) {
    scene_.name = name;
  }

  Rng& rng() { return rng_; }
  Scene take() { return std::move(scene_); }
  Scene& scene() { return scene_; }

  int addTexture(TextureKind kind, double density, int size_px) {
    scene_.textures.push_back(Texture::generate(kind, density, rng_.nextU64(), size_px));
    return static_cast<int>(scene_.textures.size()) - 1;
  }

  /// A rectangle centred at `center` whose visible side faces `normal`; `up` is any direction in
  /// the plane that should appear upwards in its texture. width_m runs along the viewer's right.
  /// texel_m > 0 tiles the texture at that resolution; texel_m <= 0 stretches it once (posters).
  void facingRect(const Eigen::Vector3d& center, const Eigen::Vector3d& normal,
                  const Eigen::Vector3d& up, double width_m, double height_m, int texture,
                  double texel_m) {
    facingRect(center, normal, up, width_m, height_m, texture, texel_m, rng_);
  }

  /// facingRect drawing its texture offset from `rng`.
  void facingRect(const Eigen::Vector3d& center, const Eigen::Vector3d& normal,
                  const Eigen::Vector3d& up, double width_m, double height_m, int texture,
                  double texel_m, Rng& rng) {
    const Eigen::Vector3d look = -normal.normalized();
    const Eigen::Vector3d right = look.cross(up).normalized();
    const Eigen::Vector3d down = look.cross(right);
    SurfaceRect rect;
    rect.edge_u_world = right * width_m;
    rect.edge_v_world = down * height_m;
    rect.origin_world = center - 0.5 * rect.edge_u_world - 0.5 * rect.edge_v_world;
    rect.texture = texture;
    const double size = scene_.textures[static_cast<std::size_t>(texture)].size();
    if (texel_m > 0.0) {
      rect.wrap_texture = true;
      rect.texels_per_m_u = rect.texels_per_m_v = 1.0 / texel_m;
      rect.texel_offset =
          Eigen::Vector2d(std::floor(rng.uniform(0.0, size)), std::floor(rng.uniform(0.0, size)));
    } else {
      rect.wrap_texture = false;
      rect.texels_per_m_u = size / width_m;
      rect.texels_per_m_v = size / height_m;
      rect.texel_offset = Eigen::Vector2d(-0.5, -0.5);
    }
    scene_.rects.push_back(rect);
  }

  /// The faces of an axis-aligned box, facing outwards (bottom omitted when on the floor).
  void box(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m, int side_texture,
           int top_texture, double texel_m, bool obstacle = true) {
    const Eigen::Vector3d center = 0.5 * (min_m + max_m);
    const Eigen::Vector3d size = max_m - min_m;
    const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
    facingRect({max_m.x(), center.y(), center.z()}, Eigen::Vector3d::UnitX(), z, size.y(), size.z(),
               side_texture, texel_m);
    facingRect({min_m.x(), center.y(), center.z()}, -Eigen::Vector3d::UnitX(), z, size.y(),
               size.z(), side_texture, texel_m);
    facingRect({center.x(), max_m.y(), center.z()}, Eigen::Vector3d::UnitY(), z, size.x(), size.z(),
               side_texture, texel_m);
    facingRect({center.x(), min_m.y(), center.z()}, -Eigen::Vector3d::UnitY(), z, size.x(),
               size.z(), side_texture, texel_m);
    facingRect({center.x(), center.y(), max_m.z()}, z, Eigen::Vector3d::UnitX(), size.y(), size.x(),
               top_texture, texel_m);
    if (min_m.z() > 1e-6) {
      facingRect({center.x(), center.y(), min_m.z()}, -z, Eigen::Vector3d::UnitX(), size.y(),
                 size.x(), top_texture, texel_m);
    }
    if (obstacle) scene_.obstacles.emplace_back(min_m, max_m);
  }

  /// A vertical wall from a to b (floor-level x, y), facing `normal_xy`, painted with the
  /// scene's gloss.
  void wall(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& normal_xy,
            double height_m, int texture) {
    const Eigen::Vector2d mid = 0.5 * (a + b);
    facingRect({mid.x(), mid.y(), 0.5 * height_m}, {normal_xy.x(), normal_xy.y(), 0.0},
               Eigen::Vector3d::UnitZ(), (b - a).norm(), height_m, texture, kWallTexelM);
    scene_.rects.back().gloss = params_.gloss;
  }

  /// A 256 px regular tiling of kTilesPerTexture tiles per side (16 px per tile); its index.
  int addTileTexture(TileStyle style, std::uint64_t seed) {
    style.tiles_per_side = kTilesPerTexture;
    scene_.textures.push_back(Texture::tiles(style, seed, 256));
    return static_cast<int>(scene_.textures.size()) - 1;
  }

  /// A corridor floor's texture and its texel size (metres): the classic worn tiles, or a regular
  /// tiling when params.floor_tile_m > 0.
  std::pair<int, double> corridorFloorTexture(double density) {
    if (params_.floor_tile_m <= 0.0) {
      return {addTexture(TextureKind::kFloorTiles, density, 512), kWallTexelM};
    }
    TileStyle style;
    style.contrast = params_.floor_tile_contrast;
    style.variation = params_.floor_tile_variation;
    style.base_luma = variety_rng_.uniform(95.0, 165.0);
    // One draw from the main stream, as for the classic floor: the rest of the scene stays put.
    const int texture = addTileTexture(style, rng_.nextU64());
    return {texture, params_.floor_tile_m / kTilesPerTexture};
  }

  /// A floor centred at (x, y), `width_m` across x and `length_m` along it, with the scene's gloss.
  void floor(double center_x, double center_y, double width_m, double length_m,
             std::pair<int, double> texture_and_texel_m) {
    facingRect({center_x, center_y, 0.0}, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX(),
               width_m, length_m, texture_and_texel_m.first, texture_and_texel_m.second);
    scene_.rects.back().gloss = params_.gloss;
  }

  /// A tiled dado band along the wall a-b (none when params.wall_tile_height_m is 0); all walls
  /// of a scene share one tile texture.
  void dado(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& normal_xy) {
    const double height = params_.wall_tile_height_m;
    if (height <= 0.0) return;
    if (dado_texture_ < 0) {
      TileStyle style;
      style.contrast = params_.wall_tile_contrast;
      style.grout_contrast = 0.3;
      style.base_luma = variety_rng_.uniform(120.0, 210.0);
      dado_texture_ = addTileTexture(style, variety_rng_.nextU64());
    }
    // 2 mm off the wall: in front of the paint, behind skirting boards, doors and posters. Its
    // draws come from the variety stream, so the rest of the scene is the same with or without.
    const Eigen::Vector2d center = 0.5 * (a + b) + normal_xy * 0.002;
    facingRect({center.x(), center.y(), 0.5 * height}, {normal_xy.x(), normal_xy.y(), 0.0},
               Eigen::Vector3d::UnitZ(), (b - a).norm(), height, dado_texture_,
               params_.wall_tile_m / kTilesPerTexture, variety_rng_);
    scene_.rects.back().gloss = std::max(params_.gloss, 0.3);  // glazed tiles
  }

  /// Ceiling lamps at the scene's spacing, with one lamp at (x, y); single_row: only along x.
  void lamps(double x, double y, double ceiling_height_m, bool single_row) {
    if (params_.lamp_spacing_m <= 0.0) return;
    scene_.lamps.single_row = single_row;
    scene_.lamps.spacing_m = params_.lamp_spacing_m;
    scene_.lamps.origin_xy = Eigen::Vector2d(x, y);
    scene_.lamps.height_m = ceiling_height_m - 0.05;
    scene_.lamps.strength = params_.lamp_strength;
  }

  /// A flat item on a wall (poster, door, frame): centred `along_m` metres from a on the wall a-b
  /// at height center_z_m, standing off the wall by offset_m.
  void onWall(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& normal_xy,
              double along_m, double center_z_m, double offset_m, double width_m, double height_m,
              int texture, double texel_m) {
    const Eigen::Vector2d direction = (b - a).normalized();
    const Eigen::Vector2d p = a + direction * along_m + normal_xy * offset_m;
    facingRect({p.x(), p.y(), center_z_m}, {normal_xy.x(), normal_xy.y(), 0.0},
               Eigen::Vector3d::UnitZ(), width_m, height_m, texture, texel_m);
  }

  /// Doors (with frames and handles), posters and a skirting board along a corridor wall.
  void decorateCorridorWall(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                            const Eigen::Vector2d& normal_xy, int door_texture, int frame_texture,
                            int skirting_texture) {
    const double length = (b - a).norm();
    onWall(a, b, normal_xy, 0.5 * length, 0.05, 0.006, length, 0.10, skirting_texture,
           kWallTexelM / 2.0);
    double along = rng_.uniform(0.8, 2.5);
    while (along < length - 1.2) {
      const double choice = rng_.uniform();
      if (params_.doors && choice < 0.35) {
        along += 0.55;
        onWall(a, b, normal_xy, along, 1.05, 0.004, 1.04, 2.10, frame_texture, 0.01);
        onWall(a, b, normal_xy, along, 1.025, 0.012, 0.90, 2.05, door_texture, 0.005);
        // Handle: a small box standing off the door.
        const Eigen::Vector2d direction = (b - a).normalized();
        const Eigen::Vector2d h = a + direction * (along + 0.34) + normal_xy * 0.012;
        const Eigen::Vector2d h2 = h + direction * 0.12 + normal_xy * 0.05;
        box({std::min(h.x(), h2.x()), std::min(h.y(), h2.y()), 0.98},
            {std::max(h.x(), h2.x()), std::max(h.y(), h2.y()), 1.01}, frame_texture, frame_texture,
            0.005, false);
        along += 0.55 + rng_.uniform(0.8, 3.0);
      } else if (params_.posters && choice < 0.75) {
        const double width = rng_.uniform(0.45, 0.9);
        const double height = width * rng_.uniform(0.7, 1.45);
        along += 0.5 * width;
        const int texture = addTexture(TextureKind::kPoster, 1.0, 256);
        onWall(a, b, normal_xy, along, rng_.uniform(1.35, 1.6), 0.008, width, height, texture, 0.0);
        along += 0.5 * width + rng_.uniform(0.6, 3.0);
      } else {
        along += rng_.uniform(1.0, 3.0);
      }
    }
  }

 private:
  SceneParams params_;
  Rng rng_;
  Rng variety_rng_;  ///< draws of the variety features (tiles, dado), apart from the layout's
  Scene scene_;
  int dado_texture_ = -1;
};

Eigen::Vector2d v2(double x, double y) { return {x, y}; }

}  // namespace

double SurfaceRect::distanceTo(const Eigen::Vector3d& p_world) const {
  const Eigen::Vector3d d = p_world - origin_world;
  const double a = std::clamp(d.dot(edge_u_world) / edge_u_world.squaredNorm(), 0.0, 1.0);
  const double b = std::clamp(d.dot(edge_v_world) / edge_v_world.squaredNorm(), 0.0, 1.0);
  return (origin_world + a * edge_u_world + b * edge_v_world - p_world).norm();
}

bool Scene::isFree(const Eigen::Vector3d& p_world, double margin_m) const {
  const Eigen::Vector3d margin = Eigen::Vector3d::Constant(margin_m);
  const Eigen::AlignedBox3d inner(bounds.min() + margin, bounds.max() - margin);
  if (!inner.contains(p_world)) return false;
  for (const auto& obstacle : obstacles) {
    const Eigen::AlignedBox3d grown(obstacle.min() - margin, obstacle.max() + margin);
    if (grown.contains(p_world)) return false;
  }
  return true;
}

const ConfigSchema<SceneParams>& SceneParams::schema() {
  using C = SceneParams;
  static const auto table =
      ConfigSchema<C>("synthetic")
          .number("texture_density", &C::texture_density, 0.0, 1.0, "",
                  "0 = nearly featureless walls .. 1 = rich marks")
          .flag("doors", &C::doors, "doors along corridor walls")
          .flag("posters", &C::posters, "posters on walls")
          .number("corridor_length_m", &C::corridor_length_m, 8.0, 200.0, "m",
                  "length of the corridor scene")
          .number("corridor_width_m", &C::corridor_width_m, 1.4, 6.0, "m",
                  "width of the corridor scene")
          .number("corridor_height_m", &C::corridor_height_m, 2.0, 5.0, "m",
                  "height of the corridor scene")
          .number("loop_length_m", &C::loop_length_m, 8.0, 100.0, "m",
                  "outer x extent of the ring corridor")
          .number("loop_width_m", &C::loop_width_m, 8.0, 100.0, "m",
                  "outer y extent of the ring corridor")
          .number("floor_tile_m", &C::floor_tile_m, 0.0, 2.0, "m",
                  "corridor floors: period of a regular tiling; 0 = worn "
                  "classic tiles")
          .number("floor_tile_contrast", &C::floor_tile_contrast, 0.0, 1.0, "",
                  "luma step between alternating floor tiles")
          .number("floor_tile_variation", &C::floor_tile_variation, 0.0, 1.0, "",
                  "per-tile random shade; 0 = identical tiles")
          .number("wall_tile_height_m", &C::wall_tile_height_m, 0.0, 2.0, "m",
                  "corridor walls: height of a tiled dado; 0 = none")
          .number("wall_tile_m", &C::wall_tile_m, 0.05, 1.0, "m", "period of the wall tiles")
          .number("wall_tile_contrast", &C::wall_tile_contrast, 0.0, 1.0, "",
                  "luma step between alternating wall tiles")
          .number("gloss", &C::gloss, 0.0, 1.0, "",
                  "specular strength of walls and floors; 0 = matte")
          .number("lamp_spacing_m", &C::lamp_spacing_m, 0.0, 20.0, "m",
                  "ceiling lamps on a grid of this spacing; 0 = none")
          .number("lamp_strength", &C::lamp_strength, 0.0, 1.0, "",
                  "how strongly lamps modulate the brightness");
  return table;
}

SceneParams SceneParams::load(Config& config) {
  SceneParams params;
  schema().load(config, params);
  return params;
}

const std::vector<std::string>& sceneNames() {
  static const std::vector<std::string> names = {"corridor", "corridor_loop", "room"};
  return names;
}

Scene makeScene(const std::string& name, const SceneParams& params, std::uint64_t seed) {
  if (name == "corridor") return makeCorridor(params, seed);
  if (name == "corridor_loop") return makeCorridorLoop(params, seed);
  if (name == "room") return makeRoom(params, seed);
  throw std::invalid_argument("unknown synthetic scene '" + name +
                              "' (allowed: corridor, corridor_loop, room)");
}

Scene makeCorridor(const SceneParams& params, std::uint64_t seed) {
  SceneBuilder builder("corridor", params, seed);
  const double length = params.corridor_length_m;
  const double half = 0.5 * params.corridor_width_m;
  const double height = params.corridor_height_m;
  const double density = params.texture_density;
  const int left_texture =
      builder.addTexture(TextureKind::kPlaster, density, params.wall_texture_px);
  const int right_texture =
      builder.addTexture(TextureKind::kPlaster, density, params.wall_texture_px);
  const int end_texture = builder.addTexture(TextureKind::kPlaster, std::max(density, 0.3), 512);
  const auto floor_texture = builder.corridorFloorTexture(density);
  const int ceiling_texture = builder.addTexture(TextureKind::kCeilingTiles, density, 512);
  const int door_texture = builder.addTexture(TextureKind::kWoodDoor, density, 512);
  const int frame_texture = builder.addTexture(TextureKind::kMetal, 0.0, 256);
  const int skirting_texture = builder.addTexture(TextureKind::kWood, 0.0, 256);
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  builder.floor(0.5 * length, 0.0, 2.0 * half, length, floor_texture);
  builder.facingRect({0.5 * length, 0.0, height}, -z, x, 2.0 * half, length, ceiling_texture,
                     kWallTexelM);
  builder.wall(v2(0, half), v2(length, half), v2(0, -1), height, left_texture);
  builder.wall(v2(0, -half), v2(length, -half), v2(0, 1), height, right_texture);
  builder.wall(v2(0, -half), v2(0, half), v2(1, 0), height, end_texture);
  builder.wall(v2(length, -half), v2(length, half), v2(-1, 0), height, end_texture);
  builder.dado(v2(0, half), v2(length, half), v2(0, -1));
  builder.dado(v2(0, -half), v2(length, -half), v2(0, 1));
  builder.lamps(0.5 * params.lamp_spacing_m, 0.0, height, true);
  builder.decorateCorridorWall(v2(0, half), v2(length, half), v2(0, -1), door_texture,
                               frame_texture, skirting_texture);
  builder.decorateCorridorWall(v2(0, -half), v2(length, -half), v2(0, 1), door_texture,
                               frame_texture, skirting_texture);
  Scene& scene = builder.scene();
  scene.bounds =
      Eigen::AlignedBox3d(Eigen::Vector3d(0, -half, 0), Eigen::Vector3d(length, half, height));
  const double lane = std::min(0.2, 0.25 * half);
  const double end = std::min(1.5, 0.2 * length);
  scene.navigation.patrol_path_xy = {v2(end, -lane), v2(length - end, -lane),
                                     v2(length - end, lane), v2(end, lane)};
  scene.navigation.first_leg_m = length - 2.0 * end;
  scene.navigation.lateral_clearance_m = std::max(0.1, half - lane - 0.45);
  scene.navigation.random_region =
      Eigen::AlignedBox3d(Eigen::Vector3d(2.0, -0.4 * half, 1.0),
                          Eigen::Vector3d(std::min(9.0, 0.4 * length), 0.4 * half, 1.8));
  scene.navigation.random_yaw_center_rad = 0.0;
  scene.navigation.random_yaw_range_rad = 0.6;
  return builder.take();
}

Scene makeCorridorLoop(const SceneParams& params, std::uint64_t seed) {
  SceneBuilder builder("corridor_loop", params, seed);
  const double a = params.loop_length_m;
  const double b = params.loop_width_m;
  const double w = std::min(params.corridor_width_m, 0.3 * std::min(a, b));
  const double height = params.corridor_height_m;
  const double density = params.texture_density;
  std::vector<int> wall_textures;
  for (int i = 0; i < 8; ++i) {
    wall_textures.push_back(
        builder.addTexture(TextureKind::kPlaster, density, params.wall_texture_px / 2));
  }
  const auto floor_texture = builder.corridorFloorTexture(density);
  const int ceiling_texture = builder.addTexture(TextureKind::kCeilingTiles, density, 512);
  const int door_texture = builder.addTexture(TextureKind::kWoodDoor, density, 512);
  const int frame_texture = builder.addTexture(TextureKind::kMetal, 0.0, 256);
  const int skirting_texture = builder.addTexture(TextureKind::kWood, 0.0, 256);
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  builder.floor(0.5 * a, 0.5 * b, b, a, floor_texture);
  builder.facingRect({0.5 * a, 0.5 * b, height}, -z, x, b, a, ceiling_texture, kWallTexelM);
  struct WallSpec {
    Eigen::Vector2d from, to, normal;
  };
  const std::vector<WallSpec> walls = {
      // Outer walls, facing inwards.
      {v2(0, 0), v2(a, 0), v2(0, 1)},
      {v2(a, 0), v2(a, b), v2(-1, 0)},
      {v2(a, b), v2(0, b), v2(0, -1)},
      {v2(0, b), v2(0, 0), v2(1, 0)},
      // The inner block's walls, facing outwards into the ring.
      {v2(w, w), v2(a - w, w), v2(0, -1)},
      {v2(a - w, w), v2(a - w, b - w), v2(1, 0)},
      {v2(a - w, b - w), v2(w, b - w), v2(0, 1)},
      {v2(w, b - w), v2(w, w), v2(-1, 0)},
  };
  for (std::size_t i = 0; i < walls.size(); ++i) {
    builder.wall(walls[i].from, walls[i].to, walls[i].normal, height, wall_textures[i]);
    builder.dado(walls[i].from, walls[i].to, walls[i].normal);
  }
  builder.lamps(0.5 * w, 0.5 * w, height, false);
  for (const auto& spec : walls) {
    builder.decorateCorridorWall(spec.from, spec.to, spec.normal, door_texture, frame_texture,
                                 skirting_texture);
  }
  Scene& scene = builder.scene();
  scene.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(a, b, height));
  scene.obstacles.emplace_back(Eigen::Vector3d(w, w, 0), Eigen::Vector3d(a - w, b - w, height));
  const double c = 0.5 * w;
  scene.navigation.patrol_path_xy = {v2(0.5 * a, c), v2(a - c, c), v2(a - c, b - c), v2(c, b - c),
                                     v2(c, c)};
  scene.navigation.first_leg_m = 0.5 * a - c;
  scene.navigation.lateral_clearance_m = std::max(0.1, c - 0.45);
  scene.navigation.random_region = Eigen::AlignedBox3d(Eigen::Vector3d(0.3 * a, 0.3 * w, 1.0),
                                                       Eigen::Vector3d(0.6 * a, 0.7 * w, 1.8));
  scene.navigation.random_yaw_center_rad = 0.0;
  scene.navigation.random_yaw_range_rad = 0.6;
  return builder.take();
}

Scene makeRoom(const SceneParams& params, std::uint64_t seed) {
  SceneBuilder builder("room", params, seed);
  const double wx = 6.0;
  const double wy = 5.0;
  const double height = 2.7;
  const double density = params.texture_density;
  const int wall_texture = builder.addTexture(TextureKind::kPlaster, density, 512);
  const int accent_texture =
      builder.addTexture(TextureKind::kPlaster, std::min(1.0, density + 0.2), 512);
  const int floor_texture = builder.addTexture(TextureKind::kFloorTiles, density, 512);
  const int ceiling_texture = builder.addTexture(TextureKind::kCeilingTiles, density, 512);
  const int wood = builder.addTexture(TextureKind::kWood, density, 256);
  const int dark_wood = builder.addTexture(TextureKind::kWoodDoor, density, 256);
  const int metal = builder.addTexture(TextureKind::kMetal, density, 256);
  const int fabric = builder.addTexture(TextureKind::kFabric, density, 256);
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  using V3 = Eigen::Vector3d;

  builder.facingRect({0.5 * wx, 0.5 * wy, 0.0}, z, x, wy, wx, floor_texture, kWallTexelM);
  builder.facingRect({0.5 * wx, 0.5 * wy, height}, -z, x, wy, wx, ceiling_texture, kWallTexelM);
  builder.wall(v2(0, 0), v2(wx, 0), v2(0, 1), height, wall_texture);
  builder.wall(v2(wx, 0), v2(wx, wy), v2(-1, 0), height, accent_texture);
  builder.wall(v2(wx, wy), v2(0, wy), v2(0, -1), height, wall_texture);
  builder.wall(v2(0, wy), v2(0, 0), v2(1, 0), height, accent_texture);

  // Door (x = wx wall), window (x = 0 wall), whiteboard (y = 0 wall), posters.
  const int door_texture = builder.addTexture(TextureKind::kWoodDoor, density, 512);
  builder.onWall(v2(wx, 0), v2(wx, wy), v2(-1, 0), 3.9, 1.05, 0.004, 1.04, 2.1, metal, 0.01);
  builder.onWall(v2(wx, 0), v2(wx, wy), v2(-1, 0), 3.9, 1.025, 0.012, 0.9, 2.05, door_texture,
                 0.005);
  const int window_texture = builder.addTexture(TextureKind::kPoster, 1.0, 256);
  builder.onWall(v2(0, wy), v2(0, 0), v2(1, 0), 1.2, 1.5, 0.01, 1.4, 1.1, window_texture, 0.0);
  const int board_texture = builder.addTexture(TextureKind::kPoster, 1.0, 512);
  builder.onWall(v2(0, 0), v2(wx, 0), v2(0, 1), 2.5, 1.55, 0.01, 1.8, 0.9, board_texture, 0.0);
  if (params.posters) {
    for (int i = 0; i < 3; ++i) {
      const int poster = builder.addTexture(TextureKind::kPoster, 1.0, 256);
      const double width = builder.rng().uniform(0.5, 0.8);
      builder.onWall(v2(wx, wy), v2(0, wy), v2(0, -1), 0.8 + 1.9 * i, 1.75, 0.008, width,
                     width * 1.3, poster, 0.0);
    }
    const int poster = builder.addTexture(TextureKind::kPoster, 1.0, 256);
    builder.onWall(v2(wx, 0), v2(wx, wy), v2(-1, 0), 1.6, 1.5, 0.008, 0.7, 0.9, poster, 0.0);
  }

  // Desks along the y = wy wall, each with a monitor and a chair.
  for (double x0 : {0.6, 3.6}) {
    builder.box(V3(x0, 4.2, 0.70), V3(x0 + 1.6, wy, 0.74), wood, wood, 0.01);
    builder.box(V3(x0, 4.2, 0.0), V3(x0 + 0.04, wy, 0.70), wood, wood, 0.01);
    builder.box(V3(x0 + 1.56, 4.2, 0.0), V3(x0 + 1.6, wy, 0.70), wood, wood, 0.01);
    const int screen = builder.addTexture(TextureKind::kPoster, 1.0, 256);
    builder.box(V3(x0 + 0.5, 4.62, 0.90), V3(x0 + 1.1, 4.66, 1.26), metal, metal, 0.005);
    builder.facingRect({x0 + 0.8, 4.615, 1.08}, -V3::UnitY(), z, 0.56, 0.32, screen, 0.0);
    builder.box(V3(x0 + 0.75, 4.66, 0.74), V3(x0 + 0.85, 4.7, 0.90), metal, metal, 0.005);
    builder.box(V3(x0 + 0.55, 3.7, 0.42), V3(x0 + 1.0, 4.1, 0.48), fabric, fabric, 0.005);
    builder.box(V3(x0 + 0.55, 4.08, 0.48), V3(x0 + 1.0, 4.14, 0.95), fabric, fabric, 0.005);
    builder.box(V3(x0 + 0.74, 3.87, 0.0), V3(x0 + 0.81, 3.94, 0.42), metal, metal, 0.005);
  }
  // Cabinet on the x = wx wall.
  builder.box(V3(5.45, 0.9, 0.0), V3(wx, 2.3, 1.8), metal, metal, 0.01);
  // Bookshelf on the x = 0 wall with rows of books.
  builder.box(V3(0.0, 2.6, 0.0), V3(0.35, 4.0, 2.0), dark_wood, dark_wood, 0.01);
  std::vector<int> book_textures;
  for (int i = 0; i < 6; ++i)
    book_textures.push_back(builder.addTexture(TextureKind::kFabric, 1.0, 64));
  for (double shelf_z : {0.1, 0.6, 1.1, 1.55}) {
    double y = 2.65;
    while (y < 3.9) {
      const double thickness = builder.rng().uniform(0.025, 0.07);
      const double book_height = builder.rng().uniform(0.2, 0.36);
      const int texture = book_textures[static_cast<std::size_t>(builder.rng().uniformInt(0, 5))];
      builder.box(
          V3(0.35, y, shelf_z),
          V3(0.35 + builder.rng().uniform(0.03, 0.08), y + thickness, shelf_z + book_height),
          texture, texture, 0.004, false);
      y += thickness + builder.rng().uniform(0.0, 0.03);
    }
  }
  builder.scene().obstacles.emplace_back(V3(0.0, 2.6, 0.0), V3(0.45, 4.0, 2.0));
  // Sofa on the y = 0 wall, a low table in front of it.
  builder.box(V3(1.7, 0.0, 0.0), V3(3.5, 0.9, 0.45), fabric, fabric, 0.005);
  builder.box(V3(1.7, 0.0, 0.45), V3(3.5, 0.25, 0.85), fabric, fabric, 0.005);
  builder.box(V3(2.0, 1.05, 0.0), V3(3.0, 1.45, 0.40), wood, wood, 0.01);

  Scene& scene = builder.scene();
  scene.bounds = Eigen::AlignedBox3d(V3(0, 0, 0), V3(wx, wy, height));
  scene.navigation.patrol_path_xy = {v2(3.0, 1.95), v2(4.4, 1.95), v2(4.4, 3.3), v2(1.6, 3.3),
                                     v2(1.6, 1.95)};
  scene.navigation.first_leg_m = 1.4;
  scene.navigation.lateral_clearance_m = 0.2;
  scene.navigation.random_region = Eigen::AlignedBox3d(V3(2.2, 2.0, 1.0), V3(3.8, 3.0, 1.8));
  scene.navigation.random_yaw_center_rad = 0.0;
  scene.navigation.random_yaw_range_rad = M_PI;
  return builder.take();
}

}  // namespace slamd::synth
