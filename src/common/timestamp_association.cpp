#include "slamd/common/timestamp_association.hpp"

#include <algorithm>
#include <cmath>
#include <tuple>

namespace slamd {

std::vector<std::pair<std::size_t, std::size_t>> associateTimestamps(
    const std::vector<double>& first_s, const std::vector<double>& second_s,
    double max_difference_s, double offset_s) {
  // Candidates: the exact associate.py condition. Both lists are sorted, so each first timestamp
  // only needs the second timestamps in a window around it (widened slightly so rounding never
  // loses a candidate; the exact test below decides).
  std::vector<std::size_t> second_order(second_s.size());
  for (std::size_t i = 0; i < second_order.size(); ++i) second_order[i] = i;
  std::sort(second_order.begin(), second_order.end(),
            [&](std::size_t a, std::size_t b) { return second_s[a] < second_s[b]; });
  std::vector<double> second_sorted(second_s.size());
  for (std::size_t i = 0; i < second_order.size(); ++i)
    second_sorted[i] = second_s[second_order[i]];

  struct Candidate {
    double difference;
    double a;
    double b;
    std::size_t first_index;
    std::size_t second_index;
  };
  std::vector<Candidate> candidates;
  const double margin = max_difference_s * 1.001 + 1e-9;
  for (std::size_t i = 0; i < first_s.size(); ++i) {
    const double a = first_s[i];
    auto it = std::lower_bound(second_sorted.begin(), second_sorted.end(), a - offset_s - margin);
    for (; it != second_sorted.end() && *it <= a - offset_s + margin; ++it) {
      const double b = *it;
      const double difference = std::abs(a - (b + offset_s));
      if (difference < max_difference_s) {
        const auto j = second_order[static_cast<std::size_t>(it - second_sorted.begin())];
        candidates.push_back({difference, a, b, i, j});
      }
    }
  }
  // Python sorts the tuples (difference, a, b).
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& x, const Candidate& y) {
    return std::tie(x.difference, x.a, x.b) < std::tie(y.difference, y.a, y.b);
  });
  std::vector<bool> first_used(first_s.size(), false);
  std::vector<bool> second_used(second_s.size(), false);
  std::vector<std::pair<std::size_t, std::size_t>> matches;
  for (const Candidate& c : candidates) {
    if (first_used[c.first_index] || second_used[c.second_index]) continue;
    first_used[c.first_index] = true;
    second_used[c.second_index] = true;
    matches.emplace_back(c.first_index, c.second_index);
  }
  std::sort(matches.begin(), matches.end(), [&](const auto& x, const auto& y) {
    return std::tie(first_s[x.first], second_s[x.second]) <
           std::tie(first_s[y.first], second_s[y.second]);
  });
  return matches;
}

}  // namespace slamd
