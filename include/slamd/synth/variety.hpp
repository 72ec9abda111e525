#pragma once
// Seeded variety for evaluation: scenes and walks that nobody tuned on.
//
// Usage:
//   std::string drawn = applyVariety(seed, config.scene, config.motion, config.sensor);
//   // or in configuration: synthetic.variety: true (the synthetic source calls it with
//   // synthetic.seed and logs `drawn`)
//
// From the seed alone it draws what issue 22 lists as the variety real corridors have:
//   - corridor width, texture density, doors and posters;
//   - floors of identical repeating tiles (period 0.25-0.8 m, checker contrast 0-0.5), or the
//     classic worn tiles; a tiled dado on the walls (period 0.1-0.3 m) or none;
//   - matte or glossy paint (moving highlights), ceiling lamps (pools of light) or none;
//   - auto-exposure drift;
//   - walks: speed, zigzag amplitude and period, looking left and right with faster yaw.
// The drawn values replace the configured ones. The draw depends only on the seed: the same seed
// gives the same world on every machine (synth's own bit-exact random numbers).
//
// Seeds 1000-1999 are the tuning set, 2000-2999 the evaluation set (docs/evaluation.md): change
// parameters while looking at tuning seeds only, and report evaluation seeds.
#include <cstdint>
#include <string>

#include "slamd/synth/motion.hpp"
#include "slamd/synth/scene.hpp"
#include "slamd/synth/sensor_model.hpp"

namespace slamd::synth {

/// Overwrites the varied fields of scene, motion and sensor with values drawn from `seed`;
/// returns them as one line of `key=value` pairs (the synthetic.* keys) for logs and reports.
std::string applyVariety(std::uint64_t seed, SceneParams& scene, MotionParams& motion,
                         SensorParams& sensor);

}  // namespace slamd::synth
