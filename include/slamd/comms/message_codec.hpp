#pragma once
// Encoding and checked decoding of any lcm-gen message type. Decoding never throws and never
// crashes on malformed input: a wrong fingerprint, a truncated buffer or an impossible length
// gives std::nullopt and a message saying why, so that receivers can count and report bad input.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "slamd/comms/message_precheck.hpp"

namespace slamd {

template <typename Message>
std::vector<std::uint8_t> encodeMessage(const Message& message) {
  std::vector<std::uint8_t> buffer(static_cast<std::size_t>(message.getEncodedSize()));
  const int written = message.encode(buffer.data(), 0, static_cast<int>(buffer.size()));
  buffer.resize(written < 0 ? 0 : static_cast<std::size_t>(written));
  return buffer;
}

template <typename Message>
std::optional<Message> decodeMessage(const void* data, std::size_t size,
                                     std::string* error = nullptr) {
  Message message;
  if (!plausibleEncoding<Message>(data, size)) {
    if (error) {
      *error = std::string("cannot decode ") + std::to_string(size) + " bytes as " +
               Message::getTypeName() +
               " (truncated, trailing bytes, or a string length or array count that does not fit)";
    }
    return std::nullopt;
  }
  int status = -1;
  try {
    // The structural check above has verified every length; anything the decoder still throws
    // (an allocation failure) is caught here.
    // GCC 12 warns, after inlining, that lcm-gen's hash variable "may be used uninitialized" when
    // the length check fails first; the generated code returns before using it.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
    status = message.decode(data, 0, static_cast<int>(size));
#pragma GCC diagnostic pop
  } catch (const std::exception& e) {
    if (error) *error = std::string("malformed ") + Message::getTypeName() + ": " + e.what();
    return std::nullopt;
  }
  if (status < 0) {
    if (error) {
      *error = std::string("cannot decode ") + std::to_string(size) + " bytes as " +
               Message::getTypeName() + " (wrong type, truncated or corrupt)";
    }
    return std::nullopt;
  }
  return message;
}

}  // namespace slamd
