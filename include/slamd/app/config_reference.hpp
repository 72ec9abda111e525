#pragma once
// The configuration reference: every key slamd reads, gathered from the areas' schemas (see
// config_schema.hpp), for `slamd --describe-config` and the README's configuration section.
//
//   for (const auto& key : describeConfiguration("mapping")) ...;   // one area
//   std::cout << configReferenceText(describeConfiguration(""));    // every area
//
// An area is a key's first section (daemon, lcm, channels, tracking, filter, mapping, backend,
// camera, capture, synthetic).

#include <string>
#include <vector>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

/// The areas, in the order of the reference.
const std::vector<std::string>& configAreas();

/// Every key of `area` (all areas when empty) with its default. Throws ConfigError naming the
/// areas when `area` is not one of them.
std::vector<ConfigKeyDescription> describeConfiguration(const std::string& area);

/// One key per paragraph: key, type, default, range and unit, then the doc and choices.
std::string configReferenceText(const std::vector<ConfigKeyDescription>& keys);
/// A JSON array of objects {key, type, default, min, max, length, choices, unit, doc}.
std::string configReferenceJson(const std::vector<ConfigKeyDescription>& keys);
/// A Markdown table per area (the README's reference, between its marker comments).
std::string configReferenceMarkdown(const std::vector<ConfigKeyDescription>& keys);

/// Loads every area's struct from `config` as the daemon and its sources do, so that
/// config.usedKeys() lists every key the program reads (tests, fuzzing).
void loadEveryConfigArea(Config& config);

}  // namespace slamd
