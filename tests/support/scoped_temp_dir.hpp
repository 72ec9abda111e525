#pragma once
// ScopedTempDir: a fresh, empty temporary folder for one test, removed with everything in it when
// the object goes out of scope, whether the test passed or failed.
//
//   const test::ScopedTempDir dir("config");          // /tmp/slamd-config-XXXXXX
//   std::ofstream(dir / "a.yaml") << "...";
//
// SLAMD_KEEP_TEST_DIRS=1 keeps every folder (the destructor prints where) for debugging; keep()
// keeps one (e.g. a failed scenario's logs).

#include <stdlib.h>  // mkdtemp

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <ostream>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>

namespace slamd::test {

class ScopedTempDir {
 public:
  explicit ScopedTempDir(const std::string& tag) {
    std::string pattern =
        (std::filesystem::temp_directory_path() / ("slamd-" + tag + "-XXXXXX")).string();
    if (mkdtemp(pattern.data()) == nullptr) {
      throw std::runtime_error("mkdtemp " + pattern + ": " + std::strerror(errno));
    }
    path_ = pattern;
  }
  ~ScopedTempDir() {
    if (path_.empty()) return;
    const char* keep_all = std::getenv("SLAMD_KEEP_TEST_DIRS");
    if (keep_ || (keep_all != nullptr && std::string(keep_all) == "1")) {
      std::fprintf(stderr, "test folder kept: %s\n", path_.c_str());
      return;
    }
    std::error_code error;  // never throw from a destructor; a leftover is only untidy
    std::filesystem::remove_all(path_, error);
  }
  ScopedTempDir(ScopedTempDir&& other) noexcept
      : path_(std::exchange(other.path_, {})), keep_(other.keep_) {}
  ScopedTempDir& operator=(ScopedTempDir&& other) noexcept {
    if (this != &other) {
      ScopedTempDir previous(std::move(*this));  // removed at the end of this scope
      path_ = std::exchange(other.path_, {});
      keep_ = other.keep_;
    }
    return *this;
  }
  ScopedTempDir(const ScopedTempDir&) = delete;
  ScopedTempDir& operator=(const ScopedTempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  operator const std::filesystem::path&() const { return path_; }  // NOLINT: reads as a path
  std::string string() const { return path_.string(); }
  friend std::filesystem::path operator/(const ScopedTempDir& dir,
                                         const std::filesystem::path& name) {
    return dir.path_ / name;
  }

  friend std::ostream& operator<<(std::ostream& out, const ScopedTempDir& dir) {
    return out << dir.path_;
  }

  /// Leave this folder in place (its path is printed at destruction).
  void keep() { keep_ = true; }

 private:
  std::filesystem::path path_;
  bool keep_ = false;
};

}  // namespace slamd::test
