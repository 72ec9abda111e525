#pragma once
// Minimal thread-safe logging to stderr: one line per call, never interleaved.
//   SLAMD_LOG_INFO("tracking") << "keyframe " << id;
// Levels below the global threshold (setLogLevel, default kInfo) are skipped cheaply.

#include <sstream>
#include <string>

namespace slamd {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3 };

void setLogLevel(LogLevel level);
LogLevel logLevel();
/// Parses "debug|info|warn|error"; throws std::invalid_argument otherwise.
LogLevel parseLogLevel(const std::string& text);

/// Text from outside (a command's argument, a file name in a message) made safe to log: bytes
/// outside printable ASCII become \xHH, and more than `max_chars` characters are cut with "...".
/// A hostile peer cannot forge log lines (newlines) or fill the log.
std::string printableExcerpt(const std::string& text, std::size_t max_chars = 80);

class LogLine {
 public:
  LogLine(LogLevel level, const char* component);
  ~LogLine();
  LogLine(const LogLine&) = delete;
  LogLine& operator=(const LogLine&) = delete;

  template <typename T>
  LogLine& operator<<(const T& value) {
    if (enabled_) stream_ << value;
    return *this;
  }

 private:
  bool enabled_;
  LogLevel level_;
  const char* component_;
  std::ostringstream stream_;
};

}  // namespace slamd

#define SLAMD_LOG_DEBUG(component) ::slamd::LogLine(::slamd::LogLevel::kDebug, component)
#define SLAMD_LOG_INFO(component) ::slamd::LogLine(::slamd::LogLevel::kInfo, component)
#define SLAMD_LOG_WARN(component) ::slamd::LogLine(::slamd::LogLevel::kWarn, component)
#define SLAMD_LOG_ERROR(component) ::slamd::LogLine(::slamd::LogLevel::kError, component)
