#include "slamd/common/motion_limits.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace slamd {

const ConfigSchema<MotionLimits>& MotionLimits::schema() {
  using C = MotionLimits;
  static const auto table =
      ConfigSchema<C>("filter")
          .number("max_angular_rate_radps", &C::max_angular_rate_radps, 0.01, 100.0, "rad/s",
                  "how fast the camera can turn: tracking vetoes an estimate that implies more "
                  "(beyond 3 sigma of its own noise), and the filter caps an increment's rotation "
                  "variance at (limit * dt)^2 per axis")
          .number("max_speed_mps", &C::max_speed_mps, 0.01, 100.0, "m/s",
                  "how fast the camera can move: the same veto and cap for the translation");
  return table;
}

MotionLimits MotionLimits::load(Config& config) {
  MotionLimits limits;
  schema().load(config, limits);
  return limits;
}

std::string MotionLimits::violation(const SE3& T_prev_curr, double dt_s, double translation_sigma_m,
                                    double rotation_sigma_rad) const {
  const double dt = std::isfinite(dt_s) ? std::max(dt_s, kMinIntervalS) : kMinIntervalS;
  const double translation_m = T_prev_curr.translation().norm();
  const double rotation_rad = rotationAngleRad(T_prev_curr.linear());
  char text[160];
  if (!std::isfinite(translation_m) || !std::isfinite(rotation_rad)) return "not finite";
  if (rotation_rad > max_angular_rate_radps * dt + 3.0 * std::max(0.0, rotation_sigma_rad)) {
    std::snprintf(text, sizeof text, "rotation of %.1f deg in %.3f s is over %.2f rad/s",
                  rotation_rad * 180.0 / M_PI, dt, max_angular_rate_radps);
    return text;
  }
  if (translation_m > max_speed_mps * dt + 3.0 * std::max(0.0, translation_sigma_m)) {
    std::snprintf(text, sizeof text, "translation of %.3f m in %.3f s is over %.2f m/s",
                  translation_m, dt, max_speed_mps);
    return text;
  }
  return {};
}

}  // namespace slamd
