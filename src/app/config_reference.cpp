#include "slamd/app/config_reference.hpp"

#include <algorithm>
#include <sstream>

#include "slamd/app/daemon_config.hpp"
#include "slamd/backend/backend_config.hpp"
#include "slamd/capture/camera_config.hpp"
#include "slamd/capture/depth_preprocessor.hpp"
#include "slamd/capture/openni2_source.hpp"
#include "slamd/capture/paced_source.hpp"
#include "slamd/capture/tum_source.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_frame_publisher.hpp"
#include "slamd/comms/lcm_frame_source.hpp"
#include "slamd/eval/json_writer.hpp"
#include "slamd/filter/filter_config.hpp"
#include "slamd/mapping/mapping_config.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "slamd/tracking/tracking_config.hpp"

namespace slamd {

namespace {

std::string areaOf(const std::string& key) { return key.substr(0, key.find('.')); }

/// Every schema, in reference order.
std::vector<ConfigKeyDescription> allKeys() {
  std::vector<ConfigKeyDescription> keys;
  const auto append = [&keys](std::vector<ConfigKeyDescription> more) {
    keys.insert(keys.end(), more.begin(), more.end());
  };
  append(DaemonConfig::schema().describe());
  append(LcmConfig::schema().describe());
  append(ChannelConfig::schema().describe());
  append(TrackingConfig::schema().describe());
  append(FilterConfig::schema().describe());
  append(MotionLimits::schema().describe());
  append(VanishingPointConfig::schema().describe());
  append(SurfaceAxesConfig::schema().describe());
  append(PlaneOdometryConfig::schema().describe());
  append(MappingConfig::schema().describe());
  append(BackendConfig::schema().describe());
  append(CameraConfig::schema().describe());
  append(PacingConfig::schema().describe());
  append(DepthPreprocessorConfig::schema().describe());
  append(TumSourceConfig::schema().describe());
  append(OpenNi2Config::schema().describe());
  append(LcmFrameSourceConfig::schema().describe());
  append(LcmFramePublisherConfig::schema().describe());
  append(SyntheticConfig::schema().describe());
  append(synth::SceneParams::schema().describe());
  append(synth::MotionParams::schema().describe());
  append(synth::SensorParams::schema().describe());
  return keys;
}

std::string markdownCell(std::string text) {
  for (std::size_t at = text.find('|'); at != std::string::npos; at = text.find('|', at + 2)) {
    text.replace(at, 1, "\\|");
  }
  return text;
}

}  // namespace

const std::vector<std::string>& configAreas() {
  static const std::vector<std::string> areas = [] {
    std::vector<std::string> out;
    for (const auto& key : allKeys()) {
      const std::string area = areaOf(key.key);
      if (std::find(out.begin(), out.end(), area) == out.end()) out.push_back(area);
    }
    return out;
  }();
  return areas;
}

std::vector<ConfigKeyDescription> describeConfiguration(const std::string& area) {
  std::vector<ConfigKeyDescription> keys = allKeys();
  if (area.empty()) return keys;
  const auto& areas = configAreas();
  if (std::find(areas.begin(), areas.end(), area) == areas.end()) {
    std::string allowed;
    for (const auto& name : areas) allowed += (allowed.empty() ? "" : ", ") + name;
    throw ConfigError("unknown configuration area '" + area + "': the areas are " + allowed);
  }
  keys.erase(std::remove_if(keys.begin(), keys.end(),
                            [&area](const auto& key) { return areaOf(key.key) != area; }),
             keys.end());
  return keys;
}

std::string configReferenceText(const std::vector<ConfigKeyDescription>& keys) {
  std::ostringstream out;
  for (const auto& key : keys) {
    out << key.key << "  (" << key.type << ", default "
        << (key.default_value.empty() ? "\"\"" : key.default_value);
    if (const std::string range = key.rangeText(); !range.empty()) out << ", " << range;
    if (!key.unit.empty()) out << ", " << key.unit;
    out << ")\n    " << key.doc << "\n";
    for (const auto& [text, doc] : key.choices) {
      if (!doc.empty()) out << "      " << text << ": " << doc << "\n";
    }
  }
  return out.str();
}

std::string configReferenceJson(const std::vector<ConfigKeyDescription>& keys) {
  eval::JsonWriter json(/*pretty=*/true);
  json.beginArray();
  for (const auto& key : keys) {
    json.beginObject().key("key").value(key.key).key("type").value(key.type);
    json.key("default").value(key.default_value);
    if (key.has_range) json.key("min").value(key.min_value).key("max").value(key.max_value);
    if (key.list_length != 0) json.key("length").value(key.list_length);
    if (!key.choices.empty()) {
      json.key("choices").beginArray();
      for (const auto& [text, doc] : key.choices) {
        json.beginObject().key("value").value(text).key("doc").value(doc).endObject();
      }
      json.endArray();
    }
    json.key("unit").value(key.unit).key("doc").value(key.doc).endObject();
  }
  json.endArray();
  return json.str() + "\n";
}

std::string configReferenceMarkdown(const std::vector<ConfigKeyDescription>& keys) {
  std::ostringstream out;
  std::string area;
  for (const auto& key : keys) {
    if (areaOf(key.key) != area) {
      area = areaOf(key.key);
      out << (out.tellp() > 0 ? "\n" : "") << "#### " << area << "\n\n"
          << "| Key | Type | Default | Range | Unit | Description |\n"
          << "|---|---|---|---|---|---|\n";
    }
    out << "| `" << key.key << "` | " << key.type << " | "
        << (key.default_value.empty() ? "" : "`" + markdownCell(key.default_value) + "`") << " | "
        << markdownCell(key.rangeText()) << " | " << key.unit << " | " << markdownCell(key.doc)
        << " |\n";
  }
  return out.str();
}

void loadEveryConfigArea(Config& config) {
  DaemonConfig::load(config);
  ChannelConfig::load(config);
  TrackingConfig::load(config);
  FilterConfig::load(config);
  MappingConfig::load(config);
  BackendConfig::load(config);
  PacingConfig::load(config);
  DepthPreprocessorConfig::load(config);
  TumSourceConfig::load(config);
  OpenNi2Config::load(config);
  LcmFrameSourceConfig::load(config);
  LcmFramePublisherConfig::load(config);
  // SyntheticConfig::load without its check that the camera has no distortion: a sample file
  // for a real camera is valid, it only cannot drive a synthetic world.
  SyntheticConfig synthetic;
  SyntheticConfig::schema().load(config, synthetic);
  synth::SceneParams::load(config);
  synth::MotionParams::load(config);
  synth::SensorParams::load(config);
}

}  // namespace slamd
