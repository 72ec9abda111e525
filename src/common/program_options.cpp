#include "slamd/common/program_options.hpp"

#include <iostream>
#include <set>
#include <sstream>

#include "slamd/common/log.hpp"

namespace slamd {

ProgramOptions::ProgramOptions(std::string program, std::string description)
    : program_(std::move(program)), description_(std::move(description)) {
  addOption("config", "FILE", "YAML configuration file (see config/)");
  addOption("set", "SECTION.KEY=VALUE", "override one configuration value (repeatable)");
  addOption("log-level", "LEVEL", "debug, info, warn or error", "info");
  addFlag("help", "show this help and exit");
}

void ProgramOptions::addOption(const std::string& name, const std::string& value_name,
                               const std::string& help, const std::string& default_value) {
  if (!specs_.count(name)) order_.push_back(name);
  specs_[name] = OptionSpec{value_name, help, default_value};
}

void ProgramOptions::addFlag(const std::string& name, const std::string& help) {
  if (!specs_.count(name)) order_.push_back(name);
  specs_[name] = OptionSpec{"", help, ""};
}

void ProgramOptions::setPositional(const std::string& names, std::size_t min_count,
                                   std::size_t max_count) {
  positional_names_ = names;
  positional_min_ = min_count;
  positional_max_ = max_count;
}

std::string ProgramOptions::usage() const {
  std::ostringstream out;
  out << "Usage: " << program_ << " [options]";
  if (!positional_names_.empty()) out << " " << positional_names_;
  out << "\n" << description_ << "\n\nOptions:\n";
  for (const auto& name : order_) {
    const OptionSpec& spec = specs_.at(name);
    std::string left = "  --" + name + (spec.value_name.empty() ? "" : " " + spec.value_name);
    if (left.size() < 34)
      left.resize(34, ' ');
    else
      left += "\n" + std::string(34, ' ');
    out << left << spec.help;
    if (!spec.default_value.empty()) out << " (default: " << spec.default_value << ")";
    out << "\n";
  }
  return out.str();
}

bool ProgramOptions::parse(int argc, const char* const* argv) {
  auto usage_error = [&](const std::string& message) {
    std::cerr << program_ << ": " << message << "\n\n" << usage();
    exit_code_ = kExitUsage;
    return false;
  };
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg.rfind("--", 0) != 0 || arg == "--") {
      positional_.push_back(arg);
      continue;
    }
    std::string name = arg.substr(2);
    std::string value;
    bool has_inline_value = false;
    const auto eq = name.find('=');
    if (eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
      has_inline_value = true;
    }
    const auto spec = specs_.find(name);
    if (spec == specs_.end()) return usage_error("unknown option --" + name);
    if (spec->second.value_name.empty()) {
      if (has_inline_value) return usage_error("option --" + name + " takes no value");
      values_[name] = "true";
      continue;
    }
    if (!has_inline_value) {
      if (i + 1 >= argc) return usage_error("option --" + name + " needs a value");
      value = argv[++i];
    }
    if (name == "set") {
      overrides_.push_back(value);
    } else {
      values_[name] = value;
    }
  }
  if (flag("help")) {
    std::cout << usage();
    exit_code_ = kExitOk;
    return false;
  }
  if (positional_.size() < positional_min_ || positional_.size() > positional_max_) {
    if (positional_names_.empty())
      return usage_error("unexpected argument '" + positional_[0] + "'");
    return usage_error("expected " + positional_names_);
  }
  try {
    setLogLevel(parseLogLevel(value("log-level")));
  } catch (const std::invalid_argument& e) {
    return usage_error(e.what());
  }
  return true;
}

std::string ProgramOptions::value(const std::string& name) const {
  const auto it = values_.find(name);
  if (it != values_.end()) return it->second;
  const auto spec = specs_.find(name);
  return spec == specs_.end() ? "" : spec->second.default_value;
}

bool ProgramOptions::has(const std::string& name) const { return values_.count(name) != 0; }

bool ProgramOptions::flag(const std::string& name) const {
  const auto it = values_.find(name);
  return it != values_.end() && it->second == "true";
}

Config ProgramOptions::loadConfig(const std::string& default_path) const {
  const std::string path = has("config") ? value("config") : default_path;
  Config config = path.empty() ? Config() : Config::fromFile(path);
  for (const auto& assignment : overrides_) config.applyOverride(assignment);
  return config;
}

void reportConfig(const Config& config, const std::string& program, UnknownKeys which) {
  auto sectionOf = [](const std::string& key) { return key.substr(0, key.find('.')); };
  std::set<std::string> sections_read;
  for (const std::string& key : config.usedKeys()) sections_read.insert(sectionOf(key));
  for (const auto& key : config.unknownKeys()) {
    if (which == UnknownKeys::kInSectionsItRead && sections_read.count(sectionOf(key)) == 0) {
      continue;
    }
    SLAMD_LOG_WARN(program.c_str()) << "unknown configuration key '" << key << "' in "
                                    << config.origin() << " (ignored; misspelt?)";
  }
  SLAMD_LOG_INFO(program.c_str()) << "effective configuration (" << config.origin() << "):\n"
                                  << config.effectiveYaml();
}

}  // namespace slamd
