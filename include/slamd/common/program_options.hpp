#pragma once
// Command-line handling shared by every slamd program: `--config FILE`, repeated
// `--set section.key=value`, `--help`, plus program-specific options declared by the caller.
//
//   ProgramOptions options("slamd-play", "Reads an RGB-D source and reports its statistics.");
//   options.addOption("source", "SOURCE", "tum:DIR|openni2[:URI]|oni:FILE|...", "synthetic:room");
//   options.addFlag("publish", "Publish frames on LCM");
//   if (!options.parse(argc, argv)) return options.exitCode();   // --help or a usage error
//   Config config = options.loadConfig();                         // file + overrides
//
// Usage errors print the message and the usage text to stderr; exitCode() is 0 after --help and
// kExitUsage (2) after an error.

#include <map>
#include <string>
#include <vector>

#include "slamd/common/config.hpp"

namespace slamd {

/// Exit codes shared by all programs.
enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = 1,       ///< runtime failure
  kExitUsage = 2,         ///< bad command line
  kExitConfigError = 3,   ///< configuration file or value invalid
  kExitSourceError = 4,   ///< input source could not be opened or failed
  kExitOutputError = 5,   ///< an output file could not be written
  kExitSessionError = 6,  ///< a session (--session-in) was refused
};

class ProgramOptions {
 public:
  ProgramOptions(std::string program, std::string description);

  /// An option taking a value: --name VALUE or --name=VALUE.
  void addOption(const std::string& name, const std::string& value_name, const std::string& help,
                 const std::string& default_value = "");
  /// A boolean flag: --name.
  void addFlag(const std::string& name, const std::string& help);
  /// Positional arguments (named for the usage text); min..max count.
  void setPositional(const std::string& names, std::size_t min_count, std::size_t max_count);

  /// Returns false when the program should exit now (help shown or usage error).
  bool parse(int argc, const char* const* argv);
  int exitCode() const { return exit_code_; }

  std::string value(const std::string& name) const;
  bool has(const std::string& name) const;  ///< given on the command line
  bool flag(const std::string& name) const;
  const std::vector<std::string>& positional() const { return positional_; }
  const std::vector<std::string>& overrides() const { return overrides_; }
  std::string usage() const;

  /// Loads --config (or the given default path when absent; empty = no file) and applies every
  /// --set. Throws ConfigError.
  Config loadConfig(const std::string& default_path = "") const;

 private:
  struct OptionSpec {
    std::string value_name;  ///< empty for flags
    std::string help;
    std::string default_value;
  };
  std::string program_;
  std::string description_;
  std::vector<std::string> order_;
  std::map<std::string, OptionSpec> specs_;
  std::map<std::string, std::string> values_;
  std::vector<std::string> positional_;
  std::string positional_names_;
  std::size_t positional_min_ = 0;
  std::size_t positional_max_ = 0;
  std::vector<std::string> overrides_;
  int exit_code_ = 0;
};

/// Which unread keys reportConfig() warns about.
enum class UnknownKeys {
  kAll,               ///< every key nothing read (the daemon, which reads every section)
  kInSectionsItRead,  ///< only keys in sections the program read some key of: a tool that shares
                      ///< the daemon's configuration file reads a few sections and must not call
                      ///< the others' keys misspelt
};

/// Logs unknown configuration keys as warnings and the effective configuration at info level;
/// every program calls it once all modules have read their sections.
void reportConfig(const Config& config, const std::string& program,
                  UnknownKeys which = UnknownKeys::kAll);

}  // namespace slamd
