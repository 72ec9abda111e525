#include "slamd/eval/metrics_report.hpp"

#include <cctype>
#include <sstream>
#include <stdexcept>

#include <opencv2/core.hpp>

#include "slamd/eval/json_writer.hpp"

namespace slamd::eval {
namespace {

// A tree of the dotted keys, for nested output.
struct Node {
  std::map<std::string, Node> children;
  bool has_number = false;
  double number = 0.0;
  bool has_text = false;
  std::string text;
};

Node& nodeAt(Node& root, const std::string& key) {
  Node* node = &root;
  std::size_t start = 0;
  while (true) {
    const auto dot = key.find('.', start);
    node = &node->children[key.substr(start, dot - start)];
    if (dot == std::string::npos) return *node;
    start = dot + 1;
  }
}

void writeNode(JsonWriter& json, const Node& node) {
  if (node.has_number) {
    json.value(node.number);
  } else if (node.has_text) {
    json.value(node.text);
  } else {
    json.beginObject();
    for (const auto& [name, child] : node.children) {
      json.key(name);
      writeNode(json, child);
    }
    json.endObject();
  }
}

void flatten(const cv::FileNode& node, const std::string& path,
             std::map<std::string, double>& out) {
  const auto join = [&](const std::string& part) {
    return path.empty() ? part : path + "." + part;
  };
  if (node.isMap()) {
    for (auto it = node.begin(); it != node.end(); ++it) {
      const cv::FileNode child = *it;
      flatten(child, join(child.name()), out);
    }
  } else if (node.isSeq()) {
    for (int i = 0; i < static_cast<int>(node.size()); ++i) {
      flatten(node[i], join(std::to_string(i)), out);
    }
  } else if (node.isInt() || node.isReal()) {
    out[path] = static_cast<double>(node);
  }
}

}  // namespace

MetricsReport::MetricsReport(std::string program) : program_(std::move(program)) {}

void MetricsReport::checkKey(const std::string& key) const {
  if (key.empty() || key.front() == '.' || key.back() == '.' ||
      key.find("..") != std::string::npos) {
    throw std::invalid_argument("metrics key '" + key + "' is malformed");
  }
  for (const char c : key) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) {
      throw std::invalid_argument("metrics key '" + key + "': only letters, digits, _ - and .");
    }
  }
  if (key == "schema" || key == "program") {
    throw std::invalid_argument("metrics key '" + key + "' is reserved");
  }
  // Neither a prefix of an existing key nor extending an existing value.
  const auto conflicts = [&](const std::string& other) {
    return other != key && (other.rfind(key + ".", 0) == 0 || key.rfind(other + ".", 0) == 0);
  };
  for (const auto& entry : numbers_) {
    if (conflicts(entry.first)) {
      throw std::invalid_argument("metrics key '" + key + "' conflicts with '" + entry.first + "'");
    }
  }
  for (const auto& entry : texts_) {
    if (conflicts(entry.first)) {
      throw std::invalid_argument("metrics key '" + key + "' conflicts with '" + entry.first + "'");
    }
  }
}

void MetricsReport::set(const std::string& key, double value) {
  checkKey(key);
  texts_.erase(key);
  numbers_[key] = value;
}

void MetricsReport::setText(const std::string& key, const std::string& text) {
  checkKey(key);
  numbers_.erase(key);
  texts_[key] = text;
}

void MetricsReport::setLatency(const std::string& stage, const LatencySummary& summary) {
  const std::string prefix = "latency_ms." + stage + ".";
  set(prefix + "p50", summary.p50_ms);
  set(prefix + "p95", summary.p95_ms);
  set(prefix + "p99", summary.p99_ms);
  set(prefix + "max", summary.max_ms);
  set(prefix + "mean", summary.mean_ms);
  set(prefix + "count", static_cast<double>(summary.count));
}

void MetricsReport::setLatencySamples(const std::string& stage,
                                      const std::vector<double>& samples_ms) {
  LatencySummary summary;
  summary.count = samples_ms.size();
  if (!samples_ms.empty()) {
    const ErrorStatistics s = computeStatistics(samples_ms);
    summary.p50_ms = s.median;
    summary.p95_ms = percentile(samples_ms, 95.0);
    summary.p99_ms = percentile(samples_ms, 99.0);
    summary.max_ms = s.max;
    summary.mean_ms = s.mean;
  }
  setLatency(stage, summary);
}

void MetricsReport::setErrorStatistics(const std::string& prefix,
                                       const ErrorStatistics& statistics) {
  set(prefix + ".rmse", statistics.rmse);
  set(prefix + ".mean", statistics.mean);
  set(prefix + ".median", statistics.median);
  set(prefix + ".std", statistics.std);
  set(prefix + ".min", statistics.min);
  set(prefix + ".max", statistics.max);
  set(prefix + ".count", static_cast<double>(statistics.count));
}

std::string MetricsReport::toJson(bool pretty) const {
  Node root;
  for (const auto& [key, number] : numbers_) {
    Node& node = nodeAt(root, key);
    node.has_number = true;
    node.number = number;
  }
  for (const auto& [key, text] : texts_) {
    Node& node = nodeAt(root, key);
    node.has_text = true;
    node.text = text;
  }
  JsonWriter json(pretty);
  json.beginObject().key("schema").value(kSchema).key("program").value(program_);
  for (const auto& [name, child] : root.children) {
    json.key(name);
    writeNode(json, child);
  }
  json.endObject();
  return json.str();
}

void MetricsReport::print(std::ostream& out) const { out << toJson() << std::endl; }

std::map<std::string, double> flattenJsonNumbers(const std::string& json_text) {
  std::map<std::string, double> out;
  try {
    cv::FileStorage storage(
        json_text, cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_JSON);
    const cv::FileNode root = storage.root();
    if (!root.isMap()) throw std::runtime_error("not a JSON object");
    flatten(root, "", out);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(std::string("not a readable JSON object: ") + e.what());
  }
  return out;
}

std::string lastJsonObject(const std::string& output) {
  const auto first = output.find_first_not_of(" \t\r\n");
  if (first == std::string::npos) return "";
  const auto last = output.find_last_not_of(" \t\r\n");
  if (output[first] == '{' && output[last] == '}') {
    // The whole output may be one object (e.g. pretty-printed); the caller's parser decides.
    const std::string whole = output.substr(first, last - first + 1);
    if (whole.find('\n') != std::string::npos) {
      try {
        flattenJsonNumbers(whole);
        return whole;
      } catch (const std::runtime_error&) {
        // fall through to the last-line rule
      }
    }
  }
  std::istringstream lines(output);
  std::string line;
  std::string found;
  while (std::getline(lines, line)) {
    const auto start = line.find_first_not_of(" \t\r");
    if (start != std::string::npos && line[start] == '{') found = line.substr(start);
  }
  return found;
}

}  // namespace slamd::eval
