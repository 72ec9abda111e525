#pragma once
// Helpers for the synth tests: sources in exact mode, brute-force ray casting.

#include <limits>
#include <memory>
#include <string>

#include "slamd/common/config.hpp"
#include "slamd/synth/synthetic_source.hpp"

namespace slamd::test {

/// A synthetic source from YAML overrides (e.g. "synthetic.sensor.exact=true").
inline std::unique_ptr<SyntheticSource> makeSyntheticSource(
    const std::string& scene, const std::vector<std::string>& overrides) {
  Config config;
  for (const auto& assignment : overrides) config.applyOverride(assignment);
  return std::make_unique<SyntheticSource>(scene, SyntheticConfig::load(config));
}

/// The nearest front-facing rectangle hit by the ray origin + s * direction (s > 0), by testing
/// every rectangle: an independent reference for the renderer. Returns the hit parameter s
/// (infinity when nothing is hit) and the rectangle index in `id`.
inline double bruteForceRayCast(const synth::Scene& scene, const Eigen::Vector3d& origin,
                                const Eigen::Vector3d& direction, int& id) {
  double best = std::numeric_limits<double>::infinity();
  id = -1;
  for (std::size_t i = 0; i < scene.rects.size(); ++i) {
    const auto& rect = scene.rects[i];
    const Eigen::Vector3d n = rect.normal();
    const double denom = n.dot(direction);
    if (!(denom < 0.0)) continue;  // parallel or seen from behind
    const double s = n.dot(rect.origin_world - origin) / denom;
    if (!(s > 0.0) || s >= best) continue;
    const Eigen::Vector3d d = origin + s * direction - rect.origin_world;
    const double a = d.dot(rect.edge_u_world) / rect.edge_u_world.squaredNorm();
    const double b = d.dot(rect.edge_v_world) / rect.edge_v_world.squaredNorm();
    if (a < 0.0 || a > 1.0 || b < 0.0 || b > 1.0) continue;
    best = s;
    id = static_cast<int>(i);
  }
  return best;
}

}  // namespace slamd::test
