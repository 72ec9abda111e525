#pragma once
// ConfigSchema: the one declaration of an area's configuration keys. Each row names a key, the
// struct member it fills, its range, unit and doc; the default is the member's initialiser. The
// same table loads the struct (through Config's typed getters, so errors, effectiveYaml() and
// unknownKeys() behave as for any other read), checks structs built in code, and describes every
// key for `slamd --describe-config` and the README's reference.
//
//   const ConfigSchema<PacingConfig>& PacingConfig::schema() {
//     static const auto table = ConfigSchema<PacingConfig>("capture.pacing")
//         .choice("mode", &PacingConfig::mode, kPacingModeNames, "how frames are paced")
//         .number("speed", &PacingConfig::speed, 1e-3, 100.0, "", "realtime speed factor");
//     return table;
//   }
//   PacingConfig PacingConfig::load(Config& config) {
//     PacingConfig out;
//     schema().load(config, out);   // then cross-field checks, as code
//     return out;
//   }
//
// A row's field is a pointer to member (&T::speed) or, for a nested member, a generic lambda
// returning a reference to it ([](auto& c) -> auto& { return c.intrinsics.fx; }), so that it
// serves both loading (T&) and describing (const T&).
//
// Enums: one EnumNames table of {value, text, doc} per enum serves parsing, enumText() (the
// toString) and the description of the choice.

#include <array>
#include <cstddef>
#include <functional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "slamd/common/config.hpp"

namespace slamd {

/// One value of an enum-valued key: the value, its spelling in configuration files, what it does.
template <typename Enum>
struct EnumName {
  Enum value;
  const char* text;
  const char* doc;
};

template <typename Enum>
using EnumNames = std::vector<EnumName<Enum>>;

/// The configuration text of `value` ("unknown" when the table lacks it).
template <typename Enum>
const char* enumText(const EnumNames<Enum>& names, Enum value) {
  for (const auto& name : names) {
    if (name.value == value) return name.text;
  }
  return "unknown";
}

/// What `slamd --describe-config` says about one key.
struct ConfigKeyDescription {
  std::string key;            ///< full dotted key, "mapping.resolution_m"
  std::string type;           ///< bool | int | double | string | choice | list
  std::string default_value;  ///< as configuration text
  bool has_range = false;     ///< int and double keys: [min_value, max_value]
  double min_value = 0.0;
  double max_value = 0.0;
  std::size_t list_length = 0;                               ///< list keys: required length
  std::vector<std::pair<std::string, std::string>> choices;  ///< choice keys: {text, doc}
  std::string unit;
  std::string doc;

  /// "[0.005, 1]", "dense|octomap", "5 numbers" or "" (bool and string keys).
  std::string rangeText() const;
};

template <typename T>
class ConfigSchema {
 public:
  /// `section`: the prefix of every key of the table, without the final dot ("filter.vp").
  explicit ConfigSchema(std::string section) : section_(std::move(section)) {}

  /// An int or double key (any arithmetic member; integers are read with Config::getInt).
  template <typename Field>
  ConfigSchema&& number(const char* name, Field field, double min_value, double max_value,
                        const char* unit, const char* doc) &&;
  template <typename Field>
  ConfigSchema&& flag(const char* name, Field field, const char* doc) &&;
  template <typename Field>
  ConfigSchema&& text(const char* name, Field field, const char* doc) &&;
  /// An enum member (or a bool chosen by two words) spelt by `names`.
  template <typename Field, typename Enum>
  ConfigSchema&& choice(const char* name, Field field, const EnumNames<Enum>& names,
                        const char* doc) &&;
  /// A std::array<double, N> member, written "[a, b, ...]" with exactly N numbers.
  template <typename Field>
  ConfigSchema&& list(const char* name, Field field, const char* unit, const char* doc) &&;
  /// Replaces the described default of the last row (when the loader, not the member, sets it).
  ConfigSchema&& describedDefault(const char* text) &&;

  const std::string& section() const { return section_; }

  /// Reads every key into `object`, whose current values are the defaults. Throws ConfigError.
  void load(Config& config, T& object) const {
    for (const auto& row : rows_) row.load(config, key(row.name), object);
  }
  /// The first key of `object` out of its range or not among its choices ("" when none): for
  /// structs built in code rather than loaded.
  std::string rangeError(const T& object) const {
    for (const auto& row : rows_) {
      if (std::string error = row.check(key(row.name), object); !error.empty()) return error;
    }
    return "";
  }
  /// Every key with the defaults of `defaults`.
  std::vector<ConfigKeyDescription> describe(const T& defaults = T{}) const {
    std::vector<ConfigKeyDescription> out;
    for (const auto& row : rows_) {
      ConfigKeyDescription description = row.describe(defaults);
      description.key = key(row.name);
      if (!row.default_note.empty()) description.default_value = row.default_note;
      out.push_back(std::move(description));
    }
    return out;
  }

 private:
  struct Row {
    std::string name;
    std::string default_note;
    std::function<void(Config&, const std::string&, T&)> load;
    std::function<std::string(const std::string&, const T&)> check;
    std::function<ConfigKeyDescription(const T&)> describe;
  };

  std::string key(const std::string& name) const { return section_ + "." + name; }

  /// The member a field names in `object` (pointer to member or accessor function).
  template <typename Field, typename Object>
  static auto& member(Field field, Object& object) {
    return std::invoke(field, object);
  }

  /// A key without range: bool or string, read by `read(config, key, default)` and shown as
  /// configuration text by `show(value)`.
  template <typename Field, typename Read, typename Show>
  ConfigSchema&& plain(const char* name, Field field, const char* type, Read read, Show show,
                       const char* doc) &&;

  ConfigSchema&& add(Row row) && {
    rows_.push_back(std::move(row));
    return std::move(*this);
  }

  std::string section_;
  std::vector<Row> rows_;
};

// --- helpers shared by the rows (config_schema.cpp)
// -----------------------------------------------

namespace config_schema_detail {
std::string outOfRange(const std::string& key, double value, double min_value, double max_value);
std::string notAChoice(const std::string& key, const std::vector<std::string>& texts);
}  // namespace config_schema_detail

template <typename T>
template <typename Field>
ConfigSchema<T>&& ConfigSchema<T>::number(const char* name, Field field, double min_value,
                                          double max_value, const char* unit, const char* doc) && {
  using Value = std::decay_t<decltype(member(field, std::declval<T&>()))>;
  static_assert(std::is_arithmetic_v<Value> && !std::is_same_v<Value, bool>,
                "number(): the member must be an int or floating-point type");
  Row row;
  row.name = name;
  row.load = [=](Config& config, const std::string& key, T& object) {
    Value& value = member(field, object);
    if constexpr (std::is_integral_v<Value>) {
      value = static_cast<Value>(config.getInt(
          key, static_cast<int>(value), static_cast<int>(min_value), static_cast<int>(max_value)));
    } else {
      value = static_cast<Value>(config.getDouble(key, value, min_value, max_value));
    }
  };
  row.check = [=](const std::string& key, const T& object) {
    const double value = static_cast<double>(member(field, object));
    return value >= min_value && value <= max_value
               ? std::string()
               : config_schema_detail::outOfRange(key, value, min_value, max_value);
  };
  row.describe = [=](const T& defaults) {
    ConfigKeyDescription d;
    d.type = std::is_integral_v<Value> ? "int" : "double";
    d.default_value = formatConfigNumber(static_cast<double>(member(field, defaults)));
    d.has_range = true;
    d.min_value = min_value;
    d.max_value = max_value;
    d.unit = unit;
    d.doc = doc;
    return d;
  };
  return std::move(*this).add(std::move(row));
}

template <typename T>
template <typename Field, typename Read, typename Show>
ConfigSchema<T>&& ConfigSchema<T>::plain(const char* name, Field field, const char* type, Read read,
                                         Show show, const char* doc) && {
  Row row;
  row.name = name;
  row.load = [=](Config& config, const std::string& key, T& object) {
    auto& value = member(field, object);
    value = read(config, key, value);
  };
  row.check = [](const std::string&, const T&) { return std::string(); };
  row.describe = [=](const T& defaults) {
    ConfigKeyDescription d;
    d.type = type;
    d.default_value = show(member(field, defaults));
    d.doc = doc;
    return d;
  };
  return std::move(*this).add(std::move(row));
}

template <typename T>
template <typename Field>
ConfigSchema<T>&& ConfigSchema<T>::flag(const char* name, Field field, const char* doc) && {
  return std::move(*this).plain(
      name, field, "bool",
      [](Config& config, const std::string& key, bool value) { return config.getBool(key, value); },
      [](bool value) { return std::string(value ? "true" : "false"); }, doc);
}

template <typename T>
template <typename Field>
ConfigSchema<T>&& ConfigSchema<T>::text(const char* name, Field field, const char* doc) && {
  return std::move(*this).plain(
      name, field, "string",
      [](Config& config, const std::string& key, const std::string& value) {
        return config.getString(key, value);
      },
      [](const std::string& value) { return value; }, doc);
}

template <typename T>
template <typename Field, typename Enum>
ConfigSchema<T>&& ConfigSchema<T>::choice(const char* name, Field field,
                                          const EnumNames<Enum>& names, const char* doc) && {
  std::vector<std::string> texts;
  for (const auto& n : names) texts.push_back(n.text);
  Row row;
  row.name = name;
  // `names` is a table with static storage (declared next to its enum), so rows refer to it.
  const EnumNames<Enum>* table = &names;
  row.load = [=](Config& config, const std::string& key, T& object) {
    Enum& value = member(field, object);
    const std::string chosen = config.getChoice(key, enumText(*table, value), texts);
    for (const auto& n : *table) {
      if (chosen == n.text) value = n.value;
    }
  };
  row.check = [=](const std::string& key, const T& object) {
    for (const auto& n : *table) {
      if (n.value == member(field, object)) return std::string();
    }
    return config_schema_detail::notAChoice(key, texts);
  };
  row.describe = [=](const T& defaults) {
    ConfigKeyDescription d;
    d.type = "choice";
    d.default_value = enumText(*table, member(field, defaults));
    for (const auto& n : *table) d.choices.emplace_back(n.text, n.doc);
    d.doc = doc;
    return d;
  };
  return std::move(*this).add(std::move(row));
}

template <typename T>
template <typename Field>
ConfigSchema<T>&& ConfigSchema<T>::list(const char* name, Field field, const char* unit,
                                        const char* doc) && {
  using Value = std::decay_t<decltype(member(field, std::declval<T&>()))>;
  constexpr std::size_t kLength = std::tuple_size<Value>::value;
  Row row;
  row.name = name;
  row.load = [=](Config& config, const std::string& key, T& object) {
    Value& value = member(field, object);
    const std::vector<double> read =
        config.getDoubleList(key, std::vector<double>(value.begin(), value.end()), kLength);
    for (std::size_t i = 0; i < kLength; ++i) value[i] = read[i];
  };
  row.check = [](const std::string&, const T&) { return std::string(); };
  row.describe = [=](const T& defaults) {
    ConfigKeyDescription d;
    d.type = "list";
    const Value& value = member(field, defaults);
    d.default_value = "[";
    for (std::size_t i = 0; i < kLength; ++i) {
      d.default_value += (i ? ", " : "") + formatConfigNumber(value[i]);
    }
    d.default_value += "]";
    d.list_length = kLength;
    d.unit = unit;
    d.doc = doc;
    return d;
  };
  return std::move(*this).add(std::move(row));
}

template <typename T>
ConfigSchema<T>&& ConfigSchema<T>::describedDefault(const char* text) && {
  rows_.back().default_note = text;
  return std::move(*this);
}

}  // namespace slamd
