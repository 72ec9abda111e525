#include "slamd/capture/tum_dataset.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <tuple>

namespace slamd {

namespace {

std::vector<std::string> splitFields(const std::string& line) {
  std::vector<std::string> fields;
  std::string field;
  for (char c : line) {
    if (c == ' ' || c == '\t' || c == ',' || c == '\r') {
      if (!field.empty()) fields.push_back(std::move(field));
      field.clear();
    } else {
      field.push_back(c);
    }
  }
  if (!field.empty()) fields.push_back(std::move(field));
  return fields;
}

bool parseDouble(const std::string& text, double& value) {
  const char* begin = text.c_str();
  char* end = nullptr;
  value = std::strtod(begin, &end);
  return end != begin && *end == '\0' && std::isfinite(value);
}

// Calls `handle(line_number, fields)` for every line that is neither blank nor a '#' comment.
template <typename Handler>
void forEachDataLine(const std::string& text, Handler&& handle) {
  std::istringstream in(text);
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    handle(line_number, splitFields(line));
  }
}

}  // namespace

TumFileList parseTumFileList(const std::string& text, const std::string& source) {
  TumFileList list;
  forEachDataLine(text, [&](int line_number, const std::vector<std::string>& fields) {
    if (fields.size() < 2) return;  // associate.py ignores such lines too
    TumListEntry entry;
    entry.line = line_number;
    entry.path = fields[1];
    if (!parseDouble(fields[0], entry.timestamp_s)) {
      list.rejected.push_back(source + " line " + std::to_string(line_number) + ": timestamp '" +
                              fields[0] + "' is not a number");
      return;
    }
    if (!list.entries.empty() && entry.timestamp_s <= list.entries.back().timestamp_s) {
      std::ostringstream message;
      message.precision(17);
      message << source << " line " << line_number << ": timestamp " << entry.timestamp_s
              << " does not increase (previous " << list.entries.back().timestamp_s << " on line "
              << list.entries.back().line << ")";
      list.rejected.push_back(message.str());
      return;
    }
    list.entries.push_back(std::move(entry));
  });
  return list;
}

TumFileList readTumFileList(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  std::ostringstream text;
  text << in.rdbuf();
  return parseTumFileList(text.str(), path);
}

TumAssociationList parseTumAssociations(const std::string& text, const std::string& source) {
  TumAssociationList list;
  forEachDataLine(text, [&](int line_number, const std::vector<std::string>& fields) {
    const std::string where = source + " line " + std::to_string(line_number);
    if (fields.size() < 4) {
      list.rejected.push_back(where + ": expected 'rgb_time rgb_path depth_time depth_path', got " +
                              std::to_string(fields.size()) + " fields");
      return;
    }
    TumFramePair pair;
    if (!parseDouble(fields[0], pair.rgb_timestamp_s) ||
        !parseDouble(fields[2], pair.depth_timestamp_s)) {
      list.rejected.push_back(where + ": timestamps must be numbers");
      return;
    }
    pair.rgb_path = fields[1];
    pair.depth_path = fields[3];
    if (pair.rgb_path.rfind("depth", 0) == 0 && pair.depth_path.rfind("rgb", 0) == 0) {
      std::swap(pair.rgb_path, pair.depth_path);
      std::swap(pair.rgb_timestamp_s, pair.depth_timestamp_s);
    }
    if (!list.pairs.empty() && pair.rgb_timestamp_s <= list.pairs.back().rgb_timestamp_s) {
      list.rejected.push_back(where + ": colour timestamp " + fields[0] + " does not increase");
      return;
    }
    list.pairs.push_back(std::move(pair));
  });
  return list;
}

}  // namespace slamd
