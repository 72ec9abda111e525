#pragma once
// Timestamp association as the TUM RGB-D benchmark's associate.py defines it (used for colour /
// depth pairing and for trajectory evaluation): every pair (a, b) with |a - (b + offset)| <
// max_difference is a candidate; candidates are taken in order of increasing difference (ties by
// a, then b), each accepted when neither side is matched yet; the result is sorted by the first
// timestamp.

#include <cstddef>
#include <utility>
#include <vector>

namespace slamd {

/// Index pairs (into `first_s`, `second_s`) of the associated timestamps (seconds), sorted by
/// the first timestamp.
std::vector<std::pair<std::size_t, std::size_t>> associateTimestamps(
    const std::vector<double>& first_s, const std::vector<double>& second_s,
    double max_difference_s = 0.02, double offset_s = 0.0);

}  // namespace slamd
