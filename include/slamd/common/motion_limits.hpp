#pragma once
// MotionLimits: how fast the camera can physically move. Tracking vetoes an estimate that implies
// more (a flip found by matching a repeating pattern), the filter caps its increments' variance at
// it. The keys are filter.max_speed_mps and filter.max_angular_rate_radps (rows of this struct's
// schema, in the filter's area); FilterConfig and TrackingConfig each load a copy.

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"
#include "slamd/common/se3.hpp"

namespace slamd {

struct MotionLimits {
  double max_speed_mps = 3.0;
  double max_angular_rate_radps = 4.0;

  /// The `filter.max_speed_mps` and `filter.max_angular_rate_radps` keys.
  static const ConfigSchema<MotionLimits>& schema();
  /// Reads them (defaults above). Throws ConfigError when out of range.
  static MotionLimits load(Config& config);

  /// Empty when the motion T_prev_curr over dt_s seconds is within the limits, else a sentence
  /// saying which limit it breaks. The estimate's own standard deviations (translation_sigma_m,
  /// rotation_sigma_rad) widen the limits by three sigma, so noise alone never breaks them.
  /// dt_s below kMinIntervalS counts as kMinIntervalS.
  std::string violation(const SE3& T_prev_curr, double dt_s, double translation_sigma_m = 0.0,
                        double rotation_sigma_rad = 0.0) const;

  /// No camera of this class delivers frames closer than this (200 Hz): a shorter interval is a
  /// timestamp's jitter, not a motion's duration.
  static constexpr double kMinIntervalS = 0.005;
};

}  // namespace slamd
