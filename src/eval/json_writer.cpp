#include "slamd/eval/json_writer.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace slamd::eval {

std::string JsonWriter::escape(const std::string& text) {
  std::string out = "\"";
  for (const char c : text) {
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\t':
        out += "\\t";
        break;
      case '\r':
        out += "\\r";
        break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char buffer[8];
          std::snprintf(buffer, sizeof(buffer), "\\u%04x", static_cast<unsigned>(c));
          out += buffer;
        } else {
          out += c;
        }
    }
  }
  return out + "\"";
}

std::string JsonWriter::number(double value) {
  if (!std::isfinite(value)) return "null";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.17g", value);
  // Prefer the shortest text that reads back to the same double.
  for (int digits = 6; digits < 17; ++digits) {
    char shorter[32];
    std::snprintf(shorter, sizeof(shorter), "%.*g", digits, value);
    if (std::strtod(shorter, nullptr) == value) return shorter;
  }
  return buffer;
}

void JsonWriter::newline() {
  if (!pretty_) return;
  out_ += '\n';
  out_.append(2 * stack_.size(), ' ');
}

void JsonWriter::beforeValue() {
  if (stack_.empty()) {
    if (!out_.empty()) throw std::logic_error("JsonWriter: more than one top-level value");
    return;
  }
  Level& level = stack_.back();
  if (level.is_object) {
    if (!level.key_pending) throw std::logic_error("JsonWriter: value without a key in an object");
    level.key_pending = false;
    return;
  }
  if (!level.empty) out_ += ',';
  level.empty = false;
  newline();
}

JsonWriter& JsonWriter::key(const std::string& name) {
  if (stack_.empty() || !stack_.back().is_object || stack_.back().key_pending) {
    throw std::logic_error("JsonWriter: key '" + name + "' outside an object");
  }
  Level& level = stack_.back();
  if (!level.empty) out_ += ',';
  level.empty = false;
  level.key_pending = true;
  newline();
  out_ += escape(name);
  out_ += pretty_ ? ": " : ":";
  return *this;
}

JsonWriter& JsonWriter::beginObject() {
  beforeValue();
  out_ += '{';
  stack_.push_back({true, true, false});
  return *this;
}

JsonWriter& JsonWriter::beginArray() {
  beforeValue();
  out_ += '[';
  stack_.push_back({false, true, false});
  return *this;
}

JsonWriter& JsonWriter::endObject() {
  if (stack_.empty() || !stack_.back().is_object || stack_.back().key_pending) {
    throw std::logic_error("JsonWriter: unbalanced endObject");
  }
  const bool empty = stack_.back().empty;
  stack_.pop_back();
  if (!empty) newline();
  out_ += '}';
  return *this;
}

JsonWriter& JsonWriter::endArray() {
  if (stack_.empty() || stack_.back().is_object) {
    throw std::logic_error("JsonWriter: unbalanced endArray");
  }
  const bool empty = stack_.back().empty;
  stack_.pop_back();
  if (!empty) newline();
  out_ += ']';
  return *this;
}

JsonWriter& JsonWriter::value(double number_value) {
  beforeValue();
  out_ += number(number_value);
  return *this;
}

JsonWriter& JsonWriter::value(std::int64_t number_value) {
  beforeValue();
  out_ += std::to_string(number_value);
  return *this;
}

JsonWriter& JsonWriter::value(std::size_t number_value) {
  beforeValue();
  out_ += std::to_string(number_value);
  return *this;
}

JsonWriter& JsonWriter::value(bool flag) {
  beforeValue();
  out_ += flag ? "true" : "false";
  return *this;
}

JsonWriter& JsonWriter::value(const std::string& text) {
  beforeValue();
  out_ += escape(text);
  return *this;
}

JsonWriter& JsonWriter::null() {
  beforeValue();
  out_ += "null";
  return *this;
}

}  // namespace slamd::eval
