#include "slamd/common/config.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "slamd/common/yaml_subset.hpp"

namespace slamd {

namespace {

std::string trim(const std::string& text) {
  const auto begin = text.find_first_not_of(" \t\r\n");
  if (begin == std::string::npos) return "";
  const auto end = text.find_last_not_of(" \t\r\n");
  return text.substr(begin, end - begin + 1);
}

// Bounds on configuration text, far above any real configuration (slamd's own files are a few
// kB, three levels deep). Nesting is checked before reading, so that even flow collections
// ("[[[[...") are refused as too deep rather than as unsupported.
constexpr std::size_t kMaxConfigBytes = 1 << 20;
constexpr int kMaxConfigNesting = 64;

/// Largest nesting of the YAML text: per line, its indentation, plus the block sequences opened
/// on it ("- - x"), plus the flow collections still open ('[', '{'). An over-estimate of the real
/// nesting, which is all a bound needs.
int yamlNestingEstimate(const std::string& text) {
  int deepest = 0;
  int flow = 0;
  std::size_t line_start = 0;
  while (line_start < text.size()) {
    std::size_t line_end = text.find('\n', line_start);
    if (line_end == std::string::npos) line_end = text.size();
    std::size_t i = line_start;
    while (i < line_end && (text[i] == ' ' || text[i] == '\t')) ++i;
    int depth = static_cast<int>(i - line_start);
    while (i + 1 < line_end && text[i] == '-' && text[i + 1] == ' ') {
      depth += 2;
      i += 2;
      while (i < line_end && text[i] == ' ') ++i;
    }
    for (; i < line_end; ++i) {
      if (text[i] == '#') break;
      if (text[i] == '[' || text[i] == '{') deepest = std::max(deepest, depth + ++flow);
      if ((text[i] == ']' || text[i] == '}') && flow > 0) --flow;
    }
    deepest = std::max(deepest, depth + flow);
    line_start = line_end + 1;
  }
  return deepest;
}

bool parseDouble(const std::string& text, double& value) {
  const std::string t = trim(text);
  if (t.empty()) return false;
  char* end = nullptr;
  value = std::strtod(t.c_str(), &end);
  return end == t.c_str() + t.size();
}

bool parseInt(const std::string& text, long long& value) {
  const std::string t = trim(text);
  if (t.empty()) return false;
  char* end = nullptr;
  value = std::strtoll(t.c_str(), &end, 10);
  return end == t.c_str() + t.size();
}

std::string lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

std::string formatDouble(double value) { return formatConfigNumber(value); }

}  // namespace

std::string formatConfigNumber(double value) {
  char buffer[64];
  for (int precision = 6; precision <= 17; ++precision) {
    std::snprintf(buffer, sizeof(buffer), "%.*g", precision, value);
    if (std::strtod(buffer, nullptr) == value) break;
  }
  return buffer;
}

Config Config::fromFile(const std::string& path) {
  // Only a regular file of bounded size: a directory would read as empty (silently all defaults),
  // /dev/zero or a FIFO would be read forever.
  std::error_code error;
  const auto status = std::filesystem::status(path, error);
  if (error) {
    throw ConfigError("cannot open configuration file '" + path + "': " + error.message());
  }
  if (status.type() != std::filesystem::file_type::regular) {
    throw ConfigError("configuration file '" + path + "' is not a regular file (" +
                      (status.type() == std::filesystem::file_type::directory ? "a directory"
                                                                              : "a device, FIFO "
                                                                                "or socket") +
                      ")");
  }
  std::ifstream file(path, std::ios::binary);
  if (!file) throw ConfigError("cannot open configuration file '" + path + "'");
  std::string text(kMaxConfigBytes + 1, '\0');
  file.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(file.gcount()));
  if (text.size() > kMaxConfigBytes) {
    throw ConfigError("configuration file '" + path + "' is larger than " +
                      std::to_string(kMaxConfigBytes / 1024) + " kB");
  }
  try {
    Config config = fromYamlString(text);
    config.origin_ = path;
    return config;
  } catch (const ConfigError& e) {
    throw ConfigError("configuration file '" + path + "': " + e.what());
  }
}

Config Config::fromYamlString(const std::string& yaml_text) {
  if (yaml_text.size() > kMaxConfigBytes) {
    throw ConfigError("configuration text is larger than " +
                      std::to_string(kMaxConfigBytes / 1024) + " kB");
  }
  if (yamlNestingEstimate(yaml_text) > kMaxConfigNesting) {
    throw ConfigError("configuration text is nested more than " +
                      std::to_string(kMaxConfigNesting) + " levels deep");
  }
  Config config;
  for (const auto& [key, value] : readYamlSubset(yaml_text)) config.set(key, value);
  config.origin_ = "<string>";
  return config;
}

void Config::applyOverride(const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw ConfigError("override '" + assignment + "' is not of the form section.key=value");
  }
  const std::string key = trim(assignment.substr(0, eq));
  if (key.find('.') == std::string::npos) {
    throw ConfigError("override key '" + key + "' must name a section, as in section.key");
  }
  set(key, trim(assignment.substr(eq + 1)));
}

void Config::set(const std::string& key, const std::string& value) { values_[key] = value; }

bool Config::has(const std::string& key) const { return values_.count(key) != 0; }

const std::string* Config::rawValue(const std::string& key) const {
  const auto it = values_.find(key);
  return it == values_.end() ? nullptr : &it->second;
}

void Config::recordUsed(const std::string& key, const std::string& value) {
  used_values_[key] = value;
}

void Config::fail(const std::string& key, const std::string& value,
                  const std::string& allowed) const {
  throw ConfigError("configuration " + origin_ + ": " + key + " = '" + value + "': " + allowed);
}

double Config::getDouble(const std::string& key, double default_value, double min_value,
                         double max_value) {
  double value = default_value;
  if (const std::string* raw = rawValue(key)) {
    if (!parseDouble(*raw, value) || !std::isfinite(value)) {
      fail(key, *raw,
           "expected a number in [" + formatDouble(min_value) + ", " + formatDouble(max_value) +
               "]");
    }
  }
  if (value < min_value || value > max_value) {
    fail(key, formatDouble(value),
         "out of range [" + formatDouble(min_value) + ", " + formatDouble(max_value) + "]");
  }
  recordUsed(key, formatDouble(value));
  return value;
}

int Config::getInt(const std::string& key, int default_value, int min_value, int max_value) {
  long long value = default_value;
  if (const std::string* raw = rawValue(key)) {
    if (!parseInt(*raw, value)) {
      fail(key, *raw,
           "expected an integer in [" + std::to_string(min_value) + ", " +
               std::to_string(max_value) + "]");
    }
  }
  if (value < min_value || value > max_value) {
    fail(key, std::to_string(value),
         "out of range [" + std::to_string(min_value) + ", " + std::to_string(max_value) + "]");
  }
  recordUsed(key, std::to_string(value));
  return static_cast<int>(value);
}

bool Config::getBool(const std::string& key, bool default_value) {
  bool value = default_value;
  if (const std::string* raw = rawValue(key)) {
    const std::string t = lower(trim(*raw));
    if (t == "true" || t == "1" || t == "yes" || t == "on") {
      value = true;
    } else if (t == "false" || t == "0" || t == "no" || t == "off") {
      value = false;
    } else {
      fail(key, *raw, "expected true or false");
    }
  }
  recordUsed(key, value ? "true" : "false");
  return value;
}

std::string Config::getString(const std::string& key, const std::string& default_value) {
  const std::string* raw = rawValue(key);
  std::string value = raw ? *raw : default_value;
  recordUsed(key, value);
  return value;
}

std::string Config::getChoice(const std::string& key, const std::string& default_value,
                              const std::vector<std::string>& choices) {
  const std::string* raw = rawValue(key);
  const std::string value = raw ? trim(*raw) : default_value;
  if (std::find(choices.begin(), choices.end(), value) == choices.end()) {
    std::string allowed = "allowed values are";
    for (std::size_t i = 0; i < choices.size(); ++i) {
      allowed += (i == 0 ? " " : ", ") + choices[i];
    }
    fail(key, value, allowed);
  }
  recordUsed(key, value);
  return value;
}

std::vector<double> Config::getDoubleList(const std::string& key,
                                          const std::vector<double>& default_value,
                                          std::size_t required_length) {
  std::vector<double> values = default_value;
  const std::string* raw = rawValue(key);
  const std::string length_text = required_length
                                      ? "a list of " + std::to_string(required_length) + " numbers"
                                      : "a list of numbers [a, b, ...]";
  if (raw) {
    std::string text = trim(*raw);
    if (text.size() < 2 || text.front() != '[' || text.back() != ']') {
      fail(key, *raw, "expected " + length_text);
    }
    values.clear();
    std::stringstream items(text.substr(1, text.size() - 2));
    std::string item;
    while (std::getline(items, item, ',')) {
      if (trim(item).empty()) continue;
      double value = 0.0;
      if (!parseDouble(item, value) || !std::isfinite(value)) {
        fail(key, *raw, "expected " + length_text);
      }
      values.push_back(value);
    }
  }
  if (required_length != 0 && values.size() != required_length) {
    fail(key, raw ? *raw : "<default>", "expected " + length_text);
  }
  std::string used = "[";
  for (std::size_t i = 0; i < values.size(); ++i) {
    used += (i ? ", " : "") + formatDouble(values[i]);
  }
  recordUsed(key, used + "]");
  return values;
}

std::vector<std::string> Config::usedKeys() const {
  std::vector<std::string> keys;
  for (const auto& entry : used_values_) keys.push_back(entry.first);
  return keys;
}

std::vector<std::string> Config::unknownKeys() const {
  std::vector<std::string> unknown;
  for (const auto& entry : values_) {
    if (used_values_.count(entry.first) == 0) unknown.push_back(entry.first);
  }
  return unknown;
}

std::string Config::effectiveYaml() const {
  std::ostringstream out;
  std::string current_section;
  for (const auto& [key, value] : used_values_) {
    const auto dot = key.find('.');
    const std::string section = key.substr(0, dot);
    if (dot == std::string::npos) {
      out << key << ": " << value << "\n";
      continue;
    }
    if (section != current_section) {
      out << section << ":\n";
      current_section = section;
    }
    const std::string rest = key.substr(dot + 1);
    const bool needs_quotes = value.empty() || value.find_first_of(":#") != std::string::npos;
    out << "  " << rest << ": " << (needs_quotes ? "\"" + value + "\"" : value) << "\n";
  }
  return out.str();
}

}  // namespace slamd
