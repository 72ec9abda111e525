#pragma once
// What the planes tests share: the rendered scenes they check against, and angles.

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>

#include <Eigen/Core>

#include "slamd/common/config.hpp"
#include "slamd/synth/synthetic_source.hpp"

namespace slamd::planes {

inline constexpr double kPi = 3.14159265358979323846;

/// Surfaces of at least this area (m^2) are structural (walls, floors, ceilings): doors
/// (1.85 m^2), posters and boards are smaller.
inline constexpr double kMinStructuralAreaM2 = 3.0;

inline double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / kPi;
}

/// The scene with its default look (Kinect v1 noise model, or exact with `exact`), except that
/// corridor walls carry no doors: a door stands 12 mm proud of its wall and has a wall-like
/// colour, so it grows into the wall's segment (within the growth tolerance) and its plane then
/// lies between the two (up to 18 mm from the wall at the camera's foot point when a door fills
/// most of the view); docs/planes.md reports it.
inline std::unique_ptr<SyntheticSource> makeSource(const std::string& scene, bool exact) {
  Config config;
  if (exact) config.applyOverride("synthetic.sensor.exact=true");
  if (scene == "corridor") config.applyOverride("synthetic.doors=false");
  return std::make_unique<SyntheticSource>(scene, SyntheticConfig::load(config));
}

}  // namespace slamd::planes
