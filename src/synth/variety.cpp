#include "slamd/synth/variety.hpp"

#include <sstream>

#include "random.hpp"

namespace slamd::synth {

std::string applyVariety(std::uint64_t seed, SceneParams& scene, MotionParams& motion,
                         SensorParams& sensor) {
  Rng rng(deriveSeed(seed, 0x7A41E7, 0));
  // Every draw happens whatever the branch, in a fixed order, so adding a field at the end never
  // changes the worlds of existing seeds.
  const double width = rng.uniform(1.6, 3.0);
  const double density = rng.uniform(0.3, 0.9);
  const bool doors = rng.uniform() < 0.8;
  const bool posters = rng.uniform() < 0.7;
  const bool regular_floor = rng.uniform() < 0.7;
  const double floor_tile = rng.uniform(0.25, 0.8);
  const double floor_contrast = rng.uniform(0.0, 0.5);
  const bool identical_tiles = rng.uniform() < 0.6;
  const double floor_variation = rng.uniform(0.0, 1.0);
  const bool dado = rng.uniform() < 0.4;
  const double dado_height = rng.uniform(1.0, 1.5);
  const double wall_tile = rng.uniform(0.1, 0.3);
  const double wall_contrast = rng.uniform(0.05, 0.4);
  const bool glossy = rng.uniform() < 0.5;
  const double gloss = rng.uniform(0.2, 0.8);
  const bool lamps = rng.uniform() < 0.6;
  const double lamp_spacing = rng.uniform(2.0, 4.0);
  const double lamp_strength = rng.uniform(0.3, 0.8);
  const double exposure = rng.uniform(0.0, 0.3);
  const double speed = rng.uniform(0.6, 1.0);
  const double zigzag_amplitude = rng.uniform(0.1, 0.4);
  const double zigzag_period = rng.uniform(2.5, 5.0);
  const bool look_around = rng.uniform() < 0.5;
  const double look_around_deg = rng.uniform(5.0, 25.0);
  const double look_around_hz = rng.uniform(0.2, 0.6);

  scene.corridor_width_m = width;
  scene.texture_density = density;
  scene.doors = doors;
  scene.posters = posters;
  scene.floor_tile_m = regular_floor ? floor_tile : 0.0;
  scene.floor_tile_contrast = floor_contrast;
  scene.floor_tile_variation = identical_tiles ? 0.0 : floor_variation;
  scene.wall_tile_height_m = dado ? dado_height : 0.0;
  scene.wall_tile_m = wall_tile;
  scene.wall_tile_contrast = wall_contrast;
  scene.gloss = glossy ? gloss : 0.0;
  scene.lamp_spacing_m = lamps ? lamp_spacing : 0.0;
  scene.lamp_strength = lamp_strength;
  sensor.exposure_variation = sensor.exact_mode ? 0.0 : exposure;  // exact frames stay exact
  motion.walk_speed_mps = speed;
  motion.zigzag_amplitude_m = zigzag_amplitude;
  motion.zigzag_period_s = zigzag_period;
  motion.look_around_deg = look_around ? look_around_deg : 0.0;
  motion.look_around_hz = look_around_hz;

  std::ostringstream drawn;
  drawn.precision(3);
  drawn << "corridor_width_m=" << scene.corridor_width_m
        << " texture_density=" << scene.texture_density << " doors=" << scene.doors
        << " posters=" << scene.posters << " floor_tile_m=" << scene.floor_tile_m
        << " floor_tile_contrast=" << scene.floor_tile_contrast
        << " floor_tile_variation=" << scene.floor_tile_variation
        << " wall_tile_height_m=" << scene.wall_tile_height_m
        << " wall_tile_m=" << scene.wall_tile_m
        << " wall_tile_contrast=" << scene.wall_tile_contrast << " gloss=" << scene.gloss
        << " lamp_spacing_m=" << scene.lamp_spacing_m << " lamp_strength=" << scene.lamp_strength
        << " sensor.exposure_variation=" << sensor.exposure_variation
        << " walk_speed_mps=" << motion.walk_speed_mps
        << " zigzag_amplitude_m=" << motion.zigzag_amplitude_m
        << " zigzag_period_s=" << motion.zigzag_period_s
        << " look_around_deg=" << motion.look_around_deg
        << " look_around_hz=" << motion.look_around_hz;
  return drawn.str();
}

}  // namespace slamd::synth
