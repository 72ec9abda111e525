#include "slamd/app/command_save_path.hpp"

#include <filesystem>

#include "slamd/common/log.hpp"

namespace slamd {

namespace {

bool endsWith(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

/// Empty when `name` is an acceptable file or folder name, else why not.
std::string checkName(const std::string& name) {
  if (name.empty() || name.size() > 128) return "the file name must have 1 to 128 characters";
  if (name.front() == '.') return "the file name must not start with '.'";
  for (const char c : name) {
    const bool allowed = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                         (c >= '0' && c <= '9') || c == '.' || c == '_' || c == '-';
    if (!allowed) return "the file name may hold only letters, digits, '.', '_' and '-'";
  }
  return {};
}

/// Empty when `name` is an acceptable map file name, else why not.
std::string checkFileName(const std::string& name) {
  if (std::string problem = checkName(name); !problem.empty()) return problem;
  if (!endsWith(name, ".bt") && !endsWith(name, ".ot")) return "the file must end in .bt or .ot";
  return {};
}

}  // namespace

std::optional<std::string> resolveCommandSavePath(const std::string& argument,
                                                  const std::string& save_dir, std::string& error) {
  namespace fs = std::filesystem;
  // The argument comes from any LCM peer: logged only as a printable excerpt.
  const std::string refused = "SAVE_MAP '" + printableExcerpt(argument) + "' refused: ";
  if (save_dir.empty()) {
    error = refused + "daemon.save_dir is empty, so commands may not name a file";
    return std::nullopt;
  }
  const fs::path requested(argument);
  if (argument.find('/') != std::string::npos) {
    if (!requested.is_absolute()) {
      error = refused +
              "give a bare file name (written into daemon.save_dir) or an absolute path "
              "inside it";
      return std::nullopt;
    }
    std::error_code ec;
    const fs::path folder = fs::weakly_canonical(requested.parent_path(), ec);
    const fs::path allowed = fs::weakly_canonical(fs::absolute(save_dir, ec), ec);
    // Compared as folder paths with a trailing separator ("a/b/.." normalises to "a/").
    if (ec || (folder / "").lexically_normal() != (allowed / "").lexically_normal()) {
      error = refused + "only files directly inside daemon.save_dir (" + allowed.string() +
              ") may be written";
      return std::nullopt;
    }
  }
  const std::string name = requested.filename().string();
  const std::string problem = checkFileName(name);
  if (!problem.empty()) {
    error = refused + problem;
    return std::nullopt;
  }
  return (fs::path(save_dir) / name).string();
}

std::optional<std::string> resolveCommandSessionPath(const std::string& argument,
                                                     const std::string& save_dir,
                                                     std::string& error) {
  const std::string refused = "SAVE_SESSION '" + printableExcerpt(argument) + "' refused: ";
  if (save_dir.empty()) {
    error = refused + "daemon.save_dir is empty, so commands may not name a folder";
    return std::nullopt;
  }
  if (argument.find('/') != std::string::npos) {
    error = refused + "give a bare folder name (made inside daemon.save_dir)";
    return std::nullopt;
  }
  if (const std::string problem = checkName(argument); !problem.empty()) {
    error = refused + problem;
    return std::nullopt;
  }
  return (std::filesystem::path(save_dir) / argument).string();
}

}  // namespace slamd
