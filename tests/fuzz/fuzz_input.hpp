#pragma once
// Helpers shared by the fuzz targets in this folder.
//
// FuzzInput hands out the fuzzer's bytes as small fields (a selector, a size, a string) and then
// the rest as a payload, so that a structured target can build a message field by field from
// arbitrary bytes. It never fails: past the end it returns zeros and empty payloads.
//
// Every target defines LLVMFuzzerTestOneInput. It is linked either with libFuzzer (make fuzz:
// clang, coverage-guided, sanitizers) or with replay_main.cpp (every build: replays the seed
// corpus and the regression inputs as ordinary tests). A target lets through only the errors its
// code documents (ConfigError, FrameDecodeError, ...); anything else escaping is a finding.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "slamd/common/log.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace slamd::fuzz {

/// Rejections are logged as warnings; millions of them would drown the fuzzer's own output.
inline const bool kWarningsSilenced = (setLogLevel(LogLevel::kError), true);

class FuzzInput {
 public:
  FuzzInput(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}

  std::uint8_t byte() { return pos_ < size_ ? data_[pos_++] : 0; }
  std::uint16_t uint16() {
    const auto high = byte();
    return static_cast<std::uint16_t>((high << 8) | byte());
  }
  /// `length` bytes (fewer at the end of the input).
  std::vector<std::uint8_t> bytes(std::size_t length) {
    const std::size_t n = std::min(length, size_ - pos_);
    std::vector<std::uint8_t> out(data_ + pos_, data_ + pos_ + n);
    pos_ += n;
    return out;
  }
  /// A string whose length is the next byte.
  std::string shortString() {
    const auto out = bytes(byte());
    return std::string(out.begin(), out.end());
  }
  std::vector<std::uint8_t> rest() { return bytes(size_ - pos_); }
  std::string restAsString() {
    const auto out = rest();
    return std::string(out.begin(), out.end());
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
};

}  // namespace slamd::fuzz
