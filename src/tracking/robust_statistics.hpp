#pragma once
// Robust-estimation helpers shared by the tracking library's solvers (motion_estimation.cpp,
// dense_alignment.cpp). Private to src/tracking.

#include <algorithm>
#include <cstddef>
#include <vector>

namespace slamd {

/// Huber weight for a whitened residual of magnitude s (IRLS), threshold k.
inline double huberWeight(double s, double k) { return s <= k ? 1.0 : k / s; }

/// Huber cost of a whitened residual of magnitude s: s^2 inside k, 2ks - k^2 beyond (twice the
/// textbook rho, so that inside k it equals the squared residual).
inline double huberCost(double s, double k) { return s <= k ? s * s : 2.0 * k * s - k * k; }

/// Median of values (reordered in place); 0 when empty.
inline double medianInPlace(std::vector<double>& values) {
  if (values.empty()) return 0.0;
  const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

}  // namespace slamd
