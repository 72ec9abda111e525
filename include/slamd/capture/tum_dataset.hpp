#pragma once
// TUM RGB-D dataset file lists and timestamp association, as the benchmark's tools define them.
//
// File lists (rgb.txt, depth.txt): one `timestamp path` per line; '#' starts a comment line;
// fields are separated by any mix of spaces, tabs and commas; lines with fewer than two fields
// are ignored. Timestamps are seconds as double, exactly as written.
//
// Colour and depth are paired with associateTimestamps() (common/timestamp_association.hpp),
// which reproduces associate.py.

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "slamd/common/timestamp_association.hpp"

namespace slamd {

struct TumListEntry {
  double timestamp_s = 0.0;
  std::string path;  ///< relative to the dataset folder, as written
  int line = 0;      ///< 1-based line number in the list file
};

struct TumFileList {
  std::vector<TumListEntry> entries;  ///< strictly increasing timestamps, in file order
  /// Lines rejected because their timestamp did not increase, or was not a number: each a
  /// sentence naming the file and line.
  std::vector<std::string> rejected;
};

/// One colour/depth pair to be read.
struct TumFramePair {
  double rgb_timestamp_s = 0.0;
  std::string rgb_path;  ///< relative to the dataset folder
  double depth_timestamp_s = 0.0;
  std::string depth_path;
};

struct TumAssociationList {
  std::vector<TumFramePair> pairs;    ///< strictly increasing colour timestamps, in file order
  std::vector<std::string> rejected;  ///< malformed or non-increasing lines, naming file and line
};

/// Parses list text; `source` names the file in messages.
TumFileList parseTumFileList(const std::string& text, const std::string& source);

/// Reads a list file; throws std::runtime_error naming the file when it cannot be read.
TumFileList readTumFileList(const std::string& path);

/// Parses an associations file (associate.py's output: `rgb_time rgb_path depth_time
/// depth_path` per line; when the first path is under depth/ and the second under rgb/, the
/// order is taken as depth first).
TumAssociationList parseTumAssociations(const std::string& text, const std::string& source);

}  // namespace slamd
