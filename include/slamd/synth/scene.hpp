#pragma once
// Synthetic indoor scenes: textured planar rectangles (walls, floor, ceiling, doors, posters, the
// faces of furniture boxes) plus navigation hints that the trajectory generator uses to keep the
// camera in free space.
//
// Usage:
//   SceneParams params;                  // or SceneParams::load(config) for "synthetic.*"
//   params.texture_density = 0.1;        // nearly featureless walls
//   Scene scene = makeScene("corridor", params, /*seed=*/42);   // throws std::invalid_argument
//   Renderer renderer(scene, intrinsics);                      // see renderer.hpp
//
// World frame of every scene: z up, metres; the floor is z = 0. The corridor runs along +x from
// x = 0 to its length with its centre line on y = 0; the loop corridor is a rectangular ring in the
// quadrant x, y >= 0; the room spans [0, width] x [0, depth]. A scene is immutable once built and
// depends only on its name, parameters and seed (bit-identical across runs).

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "slamd/common/config_schema.hpp"
#include "slamd/synth/texture.hpp"

namespace slamd::synth {

/// A one-sided textured rectangle. Seen from its front (the side `normal()` points to), edge_u
/// points right and edge_v points down, so textures appear upright; from behind it is invisible
/// (back-face culled), so every surface of a scene faces the free space.
struct SurfaceRect {
  Eigen::Vector3d origin_world =
      Eigen::Vector3d::Zero();  ///< top-left corner seen from the front, metres
  Eigen::Vector3d edge_u_world = Eigen::Vector3d::UnitX();  ///< top edge, left to right, metres
  Eigen::Vector3d edge_v_world = Eigen::Vector3d::UnitY();  ///< left edge, top to bottom, metres
  int texture = 0;                                          ///< index into Scene::textures
  bool wrap_texture = true;      ///< tile the texture (walls) or stretch it once (posters)
  double texels_per_m_u = 50.0;  ///< texture resolution along edge_u
  double texels_per_m_v = 50.0;  ///< texture resolution along edge_v
  Eigen::Vector2d texel_offset = Eigen::Vector2d::Zero();  ///< texel at the origin corner
  /// Specular reflectance of glossy paint or polished tiles: 0 = matte .. 1 = strong highlights
  /// (Blinn-Phong, white, moving with the viewpoint).
  double gloss = 0.0;

  /// Unit normal on the visible side.
  Eigen::Vector3d normal() const { return edge_v_world.cross(edge_u_world).normalized(); }
  /// Euclidean distance (metres) from a world point to the rectangle (its closed surface).
  double distanceTo(const Eigen::Vector3d& p_world) const;
};

/// Everything a scene builder reads from configuration ("synthetic.*").
struct SceneParams {
  double texture_density = 0.6;  ///< 0 = nearly featureless walls .. 1 = rich marks
  bool doors = true;             ///< doors along corridor walls
  bool posters = true;           ///< posters on walls
  double corridor_length_m = 30.0;
  double corridor_width_m = 2.0;
  double corridor_height_m = 2.6;
  double loop_length_m = 16.0;  ///< outer x extent of the ring corridor
  double loop_width_m = 10.0;   ///< outer y extent of the ring corridor
  int wall_texture_px = 1024;   ///< wall texture side (power of two), 2 cm per texel
  /// Corridor floors: 0 keeps the classic worn tiles; > 0 lays a regular tiling of this period
  /// (metres), identical tiles in a checker of floor_tile_contrast, the repeating pattern that
  /// fools descriptor matching.
  double floor_tile_m = 0.0;
  double floor_tile_contrast = 0.2;   ///< luma step between alternating tiles, 0..1
  double floor_tile_variation = 0.0;  ///< per-tile random shade, 0 = identical tiles
  /// Corridor walls: a tiled dado band from the floor up to this height (metres), 0 = none.
  double wall_tile_height_m = 0.0;
  double wall_tile_m = 0.15;        ///< period of the wall tiles, metres
  double wall_tile_contrast = 0.1;  ///< luma step between alternating wall tiles, 0..1
  double gloss = 0.0;               ///< specular strength of walls and floor, 0 = matte paint
  /// Ceiling lamps on a square grid of this spacing (metres), 0 = none: pools of light and
  /// darker stretches between them, and highlights on glossy surfaces.
  double lamp_spacing_m = 0.0;
  double lamp_strength = 0.5;  ///< how strongly lamps modulate the brightness, 0..1

  /// The scene's `synthetic.*` keys (rows in scene.cpp).
  static const ConfigSchema<SceneParams>& schema();
  static SceneParams load(Config& config);
};

/// Where a camera may go in a scene (for the trajectory generator).
struct NavigationHints {
  /// A closed path in free space (x, y in metres), followed by the walk, robot and loop motions;
  /// it starts at its first point and is closed back to it.
  std::vector<Eigen::Vector2d> patrol_path_xy;
  /// Length (metres) of the first leg for the zigzag walk's natural length (down the corridor).
  double first_leg_m = 0.0;
  /// Free box for random 6-DoF motion (camera centre), metres.
  Eigen::AlignedBox3d random_region;
  /// Random motion's viewing direction: yaw about world z (radians) centre and +- range.
  double random_yaw_center_rad = 0.0;
  double random_yaw_range_rad = 0.5;
  /// Free corridor half-width around the patrol path for the zigzag (metres).
  double lateral_clearance_m = 0.4;
};

/// Point lamps at the nodes of a horizontal grid under the ceiling (or along one row in x).
struct LampGrid {
  double spacing_m = 0.0;                               ///< 0 = no lamps
  Eigen::Vector2d origin_xy = Eigen::Vector2d::Zero();  ///< one lamp's x, y (metres)
  double height_m = 2.5;                                ///< lamp height (metres)
  bool single_row = false;  ///< one row along x through origin_xy (corridors)
  /// How strongly the lamps modulate the brightness: 0 = even light .. 1 = dark between lamps.
  double strength = 0.0;
};

struct Scene {
  std::string name;
  std::vector<Texture> textures;
  std::vector<SurfaceRect> rects;
  /// Axis-aligned solids the camera must stay out of (furniture, the loop's inner block), metres.
  std::vector<Eigen::AlignedBox3d> obstacles;
  /// The enclosing free volume (walls, floor, ceiling), metres.
  Eigen::AlignedBox3d bounds;
  NavigationHints navigation;
  LampGrid lamps;  ///< ceiling lamps (spacing 0: none)

  /// True when p lies inside the bounds and at least margin_m from every wall, floor, ceiling and
  /// obstacle.
  bool isFree(const Eigen::Vector3d& p_world, double margin_m) const;
};

/// The scene names makeScene() knows.
const std::vector<std::string>& sceneNames();

/// Builds "corridor", "corridor_loop" or "room"; throws std::invalid_argument for other names.
Scene makeScene(const std::string& name, const SceneParams& params, std::uint64_t seed);

Scene makeCorridor(const SceneParams& params, std::uint64_t seed);
Scene makeCorridorLoop(const SceneParams& params, std::uint64_t seed);
Scene makeRoom(const SceneParams& params, std::uint64_t seed);

}  // namespace slamd::synth
