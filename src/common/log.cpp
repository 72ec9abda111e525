#include "slamd/common/log.hpp"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <stdexcept>

namespace slamd {

namespace {
std::atomic<int> g_log_level{static_cast<int>(LogLevel::kInfo)};
std::mutex g_log_mutex;

const char* levelName(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarn:
      return "warn";
    case LogLevel::kError:
      return "error";
  }
  return "?";
}
}  // namespace

void setLogLevel(LogLevel level) { g_log_level.store(static_cast<int>(level)); }

LogLevel logLevel() { return static_cast<LogLevel>(g_log_level.load()); }

LogLevel parseLogLevel(const std::string& text) {
  if (text == "debug") return LogLevel::kDebug;
  if (text == "info") return LogLevel::kInfo;
  if (text == "warn") return LogLevel::kWarn;
  if (text == "error") return LogLevel::kError;
  throw std::invalid_argument("log level '" + text +
                              "': allowed values are debug, info, warn, error");
}

LogLine::LogLine(LogLevel level, const char* component)
    : enabled_(static_cast<int>(level) >= g_log_level.load(std::memory_order_relaxed)),
      level_(level),
      component_(component) {}

LogLine::~LogLine() {
  if (!enabled_) return;
  const auto now = std::chrono::system_clock::now();
  const std::time_t seconds = std::chrono::system_clock::to_time_t(now);
  const auto millis =
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm local{};
  localtime_r(&seconds, &local);
  char stamp[32];
  std::strftime(stamp, sizeof(stamp), "%H:%M:%S", &local);
  const std::string text = stream_.str();
  // One fprintf per line under a mutex: lines from several threads never interleave.
  std::lock_guard<std::mutex> lock(g_log_mutex);
  std::fprintf(stderr, "%s.%03d [%s] %s: %s\n", stamp, static_cast<int>(millis), levelName(level_),
               component_, text.c_str());
}

std::string printableExcerpt(const std::string& text, std::size_t max_chars) {
  std::string out;
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (i == max_chars) {
      out += "...";
      break;
    }
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      out += static_cast<char>(c);
    } else {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 0xf];
    }
  }
  return out;
}

}  // namespace slamd
