#pragma once
// Configuration: YAML files in config/ (read by readYamlSubset) into a flat table of dotted keys
// ("tracking.max_features"), overridden by `--set section.key=value`, then read by each module
// into its own struct with defaults and validation.
//
// Usage:
//   Config config = Config::fromFile("config/tum_fr1.yaml");    // throws ConfigError
//   config.applyOverride("tracking.frontend=fovis");            // throws ConfigError
//   TrackingConfig tracking = TrackingConfig::load(config);     // reads "tracking.*"
//   for (auto& key : config.unknownKeys()) warn(...);           // keys nobody read
//   std::cout << config.effectiveYaml();                        // every value read, with defaults
//
// A module's load() calls the typed getters; each getter records the key and the value used (the
// file's, the override's or the default), so effectiveYaml() shows the complete configuration a
// program ran with. Values out of range, of the wrong type or not among the allowed choices throw
// ConfigError with a message naming key, value and what is allowed.
//
// Not thread-safe: configuration is read at start-up on the main thread.

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace slamd {

class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The shortest text that reads back as the same double ("0.05", "1e-06"), as used values and
/// error messages write numbers.
std::string formatConfigNumber(double value);

class Config {
 public:
  Config() = default;

  /// Reads a YAML file (with or without a "%YAML:1.0" directive; see yaml_subset.hpp): a
  /// regular file of at most 1 MB, nested at most 64 levels (ConfigError otherwise).
  static Config fromFile(const std::string& path);
  /// Reads YAML text (for tests and embedded defaults).
  static Config fromYamlString(const std::string& yaml_text);

  /// Applies "section.key=value"; the value replaces what the file said. Sequences are written
  /// "[a, b, c]".
  void applyOverride(const std::string& assignment);
  void set(const std::string& key, const std::string& value);

  bool has(const std::string& key) const;

  double getDouble(const std::string& key, double default_value, double min_value,
                   double max_value);
  int getInt(const std::string& key, int default_value, int min_value, int max_value);
  bool getBool(const std::string& key, bool default_value);
  std::string getString(const std::string& key, const std::string& default_value);
  /// A string restricted to a set of choices (e.g. tracking.frontend: orb|sift|fovis).
  std::string getChoice(const std::string& key, const std::string& default_value,
                        const std::vector<std::string>& choices);
  /// A list of numbers, optionally of a required length (0 = any length).
  std::vector<double> getDoubleList(const std::string& key,
                                    const std::vector<double>& default_value,
                                    std::size_t required_length = 0);

  /// Every key read so far (with or without a value in the file or overrides), sorted.
  std::vector<std::string> usedKeys() const;
  /// Keys present in the file or overrides that no module read (probably misspelt).
  std::vector<std::string> unknownKeys() const;
  /// Every key read so far with the value used, as YAML grouped by section.
  std::string effectiveYaml() const;
  /// Where the configuration came from (file path or "<string>").
  const std::string& origin() const { return origin_; }

 private:
  const std::string* rawValue(const std::string& key) const;
  void recordUsed(const std::string& key, const std::string& value);
  [[noreturn]] void fail(const std::string& key, const std::string& value,
                         const std::string& allowed) const;

  std::string origin_ = "<defaults>";
  std::map<std::string, std::string> values_;       ///< dotted key -> raw text
  std::map<std::string, std::string> used_values_;  ///< dotted key -> value in effect
};

}  // namespace slamd
