#pragma once
// JsonWriter: a small streaming JSON writer (slamd has no JSON library; cv::FileStorage reads
// JSON but cannot write arbitrary documents).
//
// Usage:
//   JsonWriter json(/*pretty=*/true);
//   json.beginObject().key("pairs").value(std::size_t{2223}).key("rmse").value(0.008144);
//   json.key("tags").beginArray().value("fast").endArray().endObject();
//   std::cout << json.str() << "\n";
//
// Numbers are written with 17 significant digits (they read back bit-exactly); NaN and infinity,
// which JSON cannot hold, are written as null. Strings are escaped (quotes, backslash, control
// characters). Misuse (a value without a key inside an object, unbalanced ends) throws
// std::logic_error. Not thread-safe.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace slamd::eval {

class JsonWriter {
 public:
  explicit JsonWriter(bool pretty = false) : pretty_(pretty) {}

  JsonWriter& beginObject();
  JsonWriter& endObject();
  JsonWriter& beginArray();
  JsonWriter& endArray();
  JsonWriter& key(const std::string& name);
  JsonWriter& value(double number);
  JsonWriter& value(std::int64_t number);
  JsonWriter& value(std::size_t number);
  JsonWriter& value(int number) { return value(static_cast<std::int64_t>(number)); }
  JsonWriter& value(bool flag);
  JsonWriter& value(const std::string& text);
  JsonWriter& value(const char* text) { return value(std::string(text)); }
  JsonWriter& null();

  /// The document so far (complete once every begin has its end).
  const std::string& str() const { return out_; }
  bool complete() const { return stack_.empty() && !out_.empty(); }

  static std::string escape(const std::string& text);
  /// A number as JSON text ("null" when not finite).
  static std::string number(double value);

 private:
  struct Level {
    bool is_object = false;
    bool empty = true;
    bool key_pending = false;
  };
  void beforeValue();
  void newline();

  bool pretty_;
  std::string out_;
  std::vector<Level> stack_;
};

}  // namespace slamd::eval
