#include "slamd/common/yaml_subset.hpp"

#include <cctype>
#include <vector>

#include "slamd/common/config.hpp"

namespace slamd {

namespace {

constexpr int kMaxNesting = 64;

struct Line {
  int number = 0;       ///< 1-based
  int indent = 0;       ///< leading spaces
  std::string content;  ///< without indentation, comment and trailing blanks
};

[[noreturn]] void fail(int line, const std::string& what) {
  throw ConfigError("line " + std::to_string(line) + ": " + what);
}

bool isBlank(char c) { return c == ' ' || c == '\t'; }

/// The line without its comment: '#' at the start or after a blank, outside quotes.
std::string withoutComment(const std::string& text) {
  char quote = 0;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (quote != 0) {
      if (c == '\\' && quote == '"') {
        ++i;
      } else if (c == quote) {
        quote = 0;
      }
    } else if ((c == '"' || c == '\'') && (i == 0 || isBlank(text[i - 1]) || text[i - 1] == '[' ||
                                           text[i - 1] == ',' || text[i - 1] == ':')) {
      quote = c;
    } else if (c == '#' && (i == 0 || isBlank(text[i - 1]))) {
      return text.substr(0, i);
    }
  }
  return text;
}

std::string rightTrimmed(const std::string& text) {
  const auto end = text.find_last_not_of(" \t");
  return end == std::string::npos ? "" : text.substr(0, end + 1);
}

std::string trimmed(const std::string& text) {
  const auto begin = text.find_first_not_of(" \t");
  return begin == std::string::npos ? "" : rightTrimmed(text.substr(begin));
}

std::vector<Line> splitLines(const std::string& text) {
  std::vector<Line> lines;
  std::size_t start = 0;
  for (int number = 1; start < text.size(); ++number) {
    std::size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    std::string raw = text.substr(start, end - start);
    start = end + 1;
    if (!raw.empty() && raw.back() == '\r') raw.pop_back();
    for (const char c : raw) {
      const auto byte = static_cast<unsigned char>(c);
      if ((byte < 0x20 && c != '\t') || byte == 0x7f) {
        fail(number, "control character " + std::to_string(byte) + " (not a text file?)");
      }
    }
    if (raw.rfind('%', 0) == 0) continue;  // a directive ("%YAML:1.0")
    const std::string marker = rightTrimmed(raw);
    if (marker == "---") continue;
    if (marker == "...") break;
    std::size_t indent = 0;
    while (indent < raw.size() && raw[indent] == ' ') ++indent;
    if (indent < raw.size() && raw[indent] == '\t')
      fail(number, "a tab indents the line (YAML indents with spaces)");
    Line line;
    line.number = number;
    line.indent = static_cast<int>(indent);
    line.content = rightTrimmed(withoutComment(raw.substr(indent)));
    if (!line.content.empty()) lines.push_back(std::move(line));
  }
  return lines;
}

/// A scalar's value: quotes removed (with their escapes), plain text as written.
std::string scalar(const std::string& text, int line) {
  if (text.empty()) return text;
  const char first = text.front();
  if (first == '"' || first == '\'') {
    std::string value;
    std::size_t i = 1;
    for (; i < text.size(); ++i) {
      const char c = text[i];
      if (first == '"' && c == '\\' && i + 1 < text.size()) {
        const char e = text[++i];
        value += e == 'n' ? '\n' : e == 't' ? '\t' : e;
      } else if (first == '\'' && c == '\'' && i + 1 < text.size() && text[i + 1] == '\'') {
        value += '\'';
        ++i;
      } else if (c == first) {
        break;
      } else {
        value += c;
      }
    }
    if (i >= text.size()) fail(line, "unclosed quote in " + text);
    if (i + 1 != text.size()) fail(line, "text after the closing quote in " + text);
    return value;
  }
  if (std::string("&*!|>{}[]@`").find(first) != std::string::npos) {
    fail(line,
         std::string("'") + first + "' starts a YAML construct slamd's configuration does not use");
  }
  return text;
}

class Reader {
 public:
  explicit Reader(std::vector<Line> lines) : lines_(std::move(lines)) {}

  std::map<std::string, std::string> read() {
    if (!lines_.empty()) readMap(lines_.front().indent, "", 1);
    if (next_ < lines_.size())
      fail(lines_[next_].number, "indentation does not match any key above");
    return std::move(values_);
  }

 private:
  void readMap(int indent, const std::string& prefix, int depth) {
    if (depth > kMaxNesting) {
      fail(lines_[next_].number,
           "nested more than " + std::to_string(kMaxNesting) + " levels deep");
    }
    while (next_ < lines_.size() && lines_[next_].indent >= indent) {
      const Line& line = lines_[next_];
      if (line.indent > indent) fail(line.number, "unexpected indentation");
      if (line.content == "-" || line.content.rfind("- ", 0) == 0) {
        fail(line.number, "a list item where a key was expected");
      }
      const std::size_t colon = keyEnd(line);
      const std::string key = line.content.substr(0, colon);
      const std::string rest = trimmed(line.content.substr(colon + 1));
      const std::string full_key = prefix.empty() ? key : prefix + "." + key;
      if (values_.count(full_key) != 0) fail(line.number, "'" + full_key + "' is given twice");
      ++next_;
      if (!rest.empty()) {
        values_[full_key] =
            rest.front() == '[' ? flowSequence(rest, line.number) : scalar(rest, line.number);
      } else if (next_ < lines_.size() && lines_[next_].indent >= indent &&
                 isListItem(lines_[next_])) {
        values_[full_key] = blockSequence(lines_[next_].indent);
      } else if (next_ < lines_.size() && lines_[next_].indent > indent) {
        readMap(lines_[next_].indent, full_key, depth + 1);
      } else {
        values_[full_key] = "";
      }
    }
  }

  static bool isListItem(const Line& line) {
    return line.content == "-" || line.content.rfind("- ", 0) == 0;
  }

  /// Position of the ':' ending the key; the key must be a plain name.
  static std::size_t keyEnd(const Line& line) {
    const std::string& text = line.content;
    std::size_t i = 0;
    while (i < text.size() && (std::isalnum(static_cast<unsigned char>(text[i])) ||
                               text[i] == '_' || text[i] == '-')) {
      ++i;
    }
    if (i == 0 || i >= text.size() || text[i] != ':' ||
        (i + 1 < text.size() && !isBlank(text[i + 1]))) {
      fail(line.number, "expected 'key: value' (a key of letters, digits, '_' or '-'), not '" +
                            text.substr(0, 60) + "'");
    }
    return i;
  }

  std::string blockSequence(int indent) {
    std::vector<std::string> items;
    while (next_ < lines_.size() && lines_[next_].indent == indent && isListItem(lines_[next_])) {
      const Line& line = lines_[next_];
      const std::string item = trimmed(line.content.substr(1));
      if (item.empty() || isListItem(Line{0, 0, item}) || item.find(": ") != std::string::npos ||
          item.back() == ':') {
        fail(line.number, "list items must be single values");
      }
      items.push_back(scalar(item, line.number));
      ++next_;
    }
    if (next_ < lines_.size() && lines_[next_].indent > indent) {
      fail(lines_[next_].number, "unexpected indentation after a list");
    }
    return joined(items);
  }

  /// "[a, b, c]" from `first` and, while the bracket is open, the lines after it.
  std::string flowSequence(const std::string& first, int line) {
    std::string text = first;
    while (!closes(text)) {
      if (next_ >= lines_.size()) fail(line, "'[' is never closed");
      text += " " + lines_[next_].content;
      ++next_;
    }
    if (text.back() != ']') fail(line, "text after the closing ']'");
    const std::string inner = text.substr(1, text.size() - 2);
    std::vector<std::string> items;
    if (!trimmed(inner).empty()) {
      std::size_t start = 0;
      char quote = 0;
      for (std::size_t i = 0; i <= inner.size(); ++i) {
        const char c = i < inner.size() ? inner[i] : ',';
        if (quote != 0) {
          if (c == quote) quote = 0;
        } else if (c == '"' || c == '\'') {
          quote = c;
        } else if (c == '[' || c == '{' || c == ']' || c == '}') {
          fail(line, "nested collections are not supported in a list");
        } else if (c == ',') {
          const std::string item = trimmed(inner.substr(start, i - start));
          if (item.empty()) fail(line, "an empty list item");
          items.push_back(scalar(item, line));
          start = i + 1;
        }
      }
    }
    return joined(items);
  }

  /// True when the first '[' of `text` has been closed (outside quotes).
  static bool closes(const std::string& text) {
    int open = 0;
    char quote = 0;
    for (const char c : text) {
      if (quote != 0) {
        if (c == quote) quote = 0;
      } else if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == '[') {
        ++open;
      } else if (c == ']' && --open == 0) {
        return true;
      }
    }
    return false;
  }

  static std::string joined(const std::vector<std::string>& items) {
    std::string text = "[";
    for (std::size_t i = 0; i < items.size(); ++i) text += (i ? ", " : "") + items[i];
    return text + "]";
  }

  std::vector<Line> lines_;
  std::size_t next_ = 0;
  std::map<std::string, std::string> values_;
};

}  // namespace

std::map<std::string, std::string> readYamlSubset(const std::string& text) {
  return Reader(splitLines(text)).read();
}

}  // namespace slamd
