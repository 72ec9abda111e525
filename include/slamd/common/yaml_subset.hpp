#pragma once
// The YAML that slamd's configuration files are written in, read by slamd itself: block
// mappings nested by indentation, scalars (plain, "double-quoted" or 'single-quoted'), flow
// sequences of scalars ("[0.1, 0.2]", possibly over several lines) and block sequences of
// scalars ("- a" lines), '#' comments, a "%YAML" directive and "---" / "..." markers.
//
// Why not a general YAML parser: configuration is read from files anyone may hand the daemon,
// and cv::FileStorage, which slamd used before, loops forever on some malformed text (found by
// fuzzing: "  t:0\n2, -\nb"). This reader is small enough to be total: one pass over the lines,
// nesting bounded (64 levels), every other construct (anchors, tags, flow mappings, block
// scalars, nested sequences, tabs in indentation, control characters) refused with its line.
//
//   std::map<std::string, std::string> values = readYamlSubset(text);  // throws ConfigError
//   values["camera.fx"] == "525.0"; values["camera.distortion"] == "[0.0, 0.0, 0.0, 0.0, 0.0]"
//
// Keys are flattened with '.'; values keep their text (quotes removed); sequences become
// "[a, b, c]"; a key with nothing under it has the empty value.

#include <map>
#include <string>

namespace slamd {

std::map<std::string, std::string> readYamlSubset(const std::string& text);

}  // namespace slamd
