#include "slamd/common/config_schema.hpp"

namespace slamd {

std::string ConfigKeyDescription::rangeText() const {
  if (has_range) {
    return "[" + formatConfigNumber(min_value) + ", " + formatConfigNumber(max_value) + "]";
  }
  if (list_length != 0) return std::to_string(list_length) + " numbers";
  std::string out;
  for (const auto& choice : choices) out += (out.empty() ? "" : "|") + choice.first;
  return out;
}

namespace config_schema_detail {

std::string outOfRange(const std::string& key, double value, double min_value, double max_value) {
  return key + " = " + formatConfigNumber(value) + ": out of range [" +
         formatConfigNumber(min_value) + ", " + formatConfigNumber(max_value) + "]";
}

std::string notAChoice(const std::string& key, const std::vector<std::string>& texts) {
  std::string allowed;
  for (const auto& text : texts) allowed += (allowed.empty() ? "" : ", ") + text;
  return key + ": not one of the allowed values " + allowed;
}

}  // namespace config_schema_detail

}  // namespace slamd
