#include "random.hpp"

#include <array>
#include <cmath>

namespace slamd::synth {
namespace {

constexpr int kTableSize = 65536;

double standardNormalCdf(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

/// Quantiles of N(0, 1) at (k + 0.5) / kTableSize, by Newton's method on the CDF, each started from
/// the previous quantile (a few iterations reach double precision).
std::array<float, kTableSize> makeQuantileTable() {
  std::array<float, kTableSize> table{};
  const double inv_sqrt_2pi = 1.0 / std::sqrt(2.0 * M_PI);
  double x = 0.0;
  // Upper half by Newton from the median outwards; the lower half by symmetry.
  for (int k = kTableSize / 2; k < kTableSize; ++k) {
    const double p = (k + 0.5) / kTableSize;
    for (int iteration = 0; iteration < 30; ++iteration) {
      const double density = inv_sqrt_2pi * std::exp(-0.5 * x * x);
      const double step = (standardNormalCdf(x) - p) / density;
      x -= step;
      if (std::abs(step) < 1e-13) break;
    }
    table[static_cast<std::size_t>(k)] = static_cast<float>(x);
    table[static_cast<std::size_t>(kTableSize - 1 - k)] = static_cast<float>(-x);
  }
  return table;
}

}  // namespace

std::uint64_t deriveSeed(std::uint64_t seed, std::uint64_t purpose, std::uint64_t index) {
  Rng mix(seed ^ (purpose * 0xD1B54A32D192ED03ULL));
  mix.nextU64();
  Rng second(mix.nextU64() ^ (index * 0x9E3779B97F4A7C15ULL));
  return second.nextU64();
}

const float* standardNormalTable() {
  static const std::array<float, kTableSize> table = makeQuantileTable();
  return table.data();
}

}  // namespace slamd::synth
