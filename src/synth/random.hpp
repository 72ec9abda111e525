#pragma once
// Deterministic random numbers for the synthetic worlds (internal to src/synth).
//
// std::normal_distribution and friends are implementation-defined, so the same seed could give
// different worlds with another standard library. Everything here is specified bit for bit:
// SplitMix64 for the bit stream (Steele, Lea & Flood 2014, "Fast splittable pseudorandom number
// generators"), uniform doubles from the top 53 bits, and standard normals from a fixed table of
// normal quantiles indexed by 16 random bits (fast enough for one draw per pixel per frame).

#include <cstdint>

namespace slamd::synth {

/// SplitMix64: a 64-bit state, one add and three xor-shift-multiplies per draw.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}

  std::uint64_t nextU64() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  /// Uniform in [0, 1).
  double uniform() { return static_cast<double>(nextU64() >> 11) * 0x1.0p-53; }
  /// Uniform in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// Uniform integer in [lo, hi] (inclusive); the modulo bias is below 2^-32 for small ranges.
  int uniformInt(int lo, int hi) {
    const auto span = static_cast<std::uint64_t>(static_cast<std::int64_t>(hi) - lo + 1);
    return lo + static_cast<int>(nextU64() % span);
  }
  /// Standard normal (table-based, see standardNormalFromBits).
  double normal();

 private:
  std::uint64_t state_;
};

/// A stream seed for one purpose and index (e.g. frame 17's depth noise) derived from a user seed,
/// so frames can be rendered in any order and still get the same noise.
std::uint64_t deriveSeed(std::uint64_t seed, std::uint64_t purpose, std::uint64_t index);

/// The 65536 standard normal quantiles Phi^-1((k + 0.5) / 65536): indexing it with 16 random
/// bits draws from N(0, 1) stratified into equally likely values (variance 1 - 3e-4). Hot loops
/// fetch the pointer once.
const float* standardNormalTable();

inline float standardNormalFromBits(std::uint16_t bits) { return standardNormalTable()[bits]; }

inline double Rng::normal() {
  return static_cast<double>(standardNormalFromBits(static_cast<std::uint16_t>(nextU64() >> 48)));
}

}  // namespace slamd::synth
