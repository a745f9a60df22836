#include "core/options.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <numeric>
#include <set>
#include <sstream>

namespace raytime {

int EditDistance(const std::string& a, const std::string& b) {
  std::vector<int> row(b.size() + 1);
  std::iota(row.begin(), row.end(), 0);
  for (size_t i = 1; i <= a.size(); ++i) {
    int diagonal = row[0];
    row[0] = static_cast<int>(i);
    for (size_t j = 1; j <= b.size(); ++j) {
      const int above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::string NearestKey(const std::string& key, const std::vector<std::string>& candidates) {
  std::string best;
  int best_distance = static_cast<int>(key.size()) / 2 + 1;
  for (const auto& candidate : candidates) {
    const int d = EditDistance(key, candidate);
    if (d < best_distance) {
      best_distance = d;
      best = candidate;
    }
  }
  return best;
}

std::string UnknownKeyMessage(const std::string& what, const std::string& key,
                              const std::vector<std::string>& candidates, const std::string& noun) {
  std::string message = "unknown " + noun + " '" + key + "' in " + what;
  const std::string nearest = NearestKey(key, candidates);
  if (!nearest.empty()) message += " (did you mean '" + nearest + "'?)";
  message += "; valid " + noun + "s: ";
  for (size_t i = 0; i < candidates.size(); ++i) message += (i ? ", " : "") + candidates[i];
  return message;
}

int YamlLine(const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  return mark.line >= 0 ? mark.line + 1 : 0;
}

namespace {

void CheckNoRepeatedKeys(const YAML::Node& node, const std::string& path) {
  if (node.IsSequence()) {
    for (const auto& child : node) CheckNoRepeatedKeys(child, path);
    return;
  }
  if (!node.IsMap()) return;
  std::map<std::string, int> first_line;
  for (const auto& entry : node) {
    if (entry.first.IsScalar()) {
      const auto [it, added] = first_line.emplace(entry.first.Scalar(), YamlLine(entry.first));
      if (!added) {
        ThrowInput(path, YamlLine(entry.first),
                   "key '" + entry.first.Scalar() +
                       "' appears twice in one mapping (first at line " +
                       std::to_string(it->second) + "); give it once");
      }
    }
    CheckNoRepeatedKeys(entry.second, path);
  }
}

}  // namespace

YAML::Node LoadYamlFile(const std::string& path) {
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) {
    ThrowInput(path, 0, "is a folder, not a YAML file");
  }
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    ThrowInput(path, 0, std::string("cannot read the file (") + std::strerror(errno) + ")");
  } catch (const YAML::ParserException& e) {
    ThrowInput(path, e.mark.line + 1, "YAML syntax error: " + e.msg);
  }
  CheckNoRepeatedKeys(root, path);
  return root;
}

void RequireUtf8(const std::string& text, const std::string& path, int line,
                 const std::string& what) {
  const std::string invalid = DescribeInvalidUtf8(text);
  if (invalid.empty()) return;
  ThrowInput(path, line, what + " must be UTF-8 text (" + invalid + " is not)");
}

namespace {

std::string NumberText(double value) {
  // Whole bounds in full ("at most 1000000", not "1e+06").
  if (value == std::floor(value) && std::abs(value) < 1e15) {
    return std::to_string(static_cast<long long>(value));
  }
  std::ostringstream out;
  out << value;
  return out.str();
}

std::string JoinValues(const std::vector<std::string>& values) {
  std::string text;
  for (const auto& value : values) text += (text.empty() ? "" : ", ") + value;
  return text;
}

}  // namespace

OptionRule Positive() {
  return {"positive", [](double x) { return std::isfinite(x) && x > 0; }, nullptr, nullptr, {}};
}

OptionRule NonNegative() {
  return {
      "non-negative", [](double x) { return std::isfinite(x) && x >= 0; }, nullptr, nullptr, {}};
}

OptionRule AtLeast(double min) {
  return {"at least " + NumberText(min),
          [min](double x) { return std::isfinite(x) && x >= min; },
          nullptr,
          nullptr,
          {}};
}

OptionRule Above(double min) {
  return {"above " + NumberText(min),
          [min](double x) { return std::isfinite(x) && x > min; },
          nullptr,
          nullptr,
          {}};
}

OptionRule AtMost(double max) {
  return {"at most " + NumberText(max),
          [max](double x) { return std::isfinite(x) && x <= max; },
          nullptr,
          nullptr,
          {}};
}

OptionRule Below(double max) {
  return {"below " + NumberText(max),
          [max](double x) { return std::isfinite(x) && x < max; },
          nullptr,
          nullptr,
          {}};
}

OptionRule OneOf(std::vector<std::string> values) {
  OptionRule rule;
  rule.expected = "one of: " + JoinValues(values);
  rule.text = [values](const std::string& x) {
    return std::find(values.begin(), values.end(), x) != values.end();
  };
  rule.values = std::move(values);
  return rule;
}

OptionRule NonEmpty() {
  return {"not empty",
          nullptr,
          [](const std::string& x) { return !x.empty(); },
          [](size_t size) { return size > 0; },
          {}};
}

std::string OptionDoc::HelpText() const {
  std::string text = description;
  for (const auto& rule : expected) text += "; " + rule;
  return text;
}

namespace options_detail {

std::string AliasedValue(const OptionAlias& alias, bool on, const std::string& current,
                         const std::string& initial, const std::string& path, int line,
                         const std::string& what) {
  const std::string given = "'" + alias.old_key + (on ? ": true'" : ": false'");
  if (on && current != initial && current != alias.value) {
    ThrowInput(path, line,
               what + ": " + given + " (now '" + alias.new_key + ": " + alias.value +
                   "') conflicts with " + alias.new_key + " '" + current +
                   "', set before it (by another deprecated key or a preset); choose one");
  }
  const std::string advice = on ? "write '" + alias.new_key + ": " + alias.value + "'"
                                : "leave it out (it only turns " + alias.new_key + " '" +
                                      alias.value + "' back to '" + initial + "')";
  // Said once per process: a pipeline's options are read several times (checked, validated,
  // configured for the cache and the run), and a --set once alone and once in its pipeline.
  static std::mutex mutex;
  static std::set<std::string> said;
  const std::string message = what + ": " + given + " is deprecated; " + advice;
  {
    const std::lock_guard<std::mutex> lock(mutex);
    if (said.insert(message).second) spdlog::warn(Located(path, line, message));
  }
  if (on) return alias.value;
  return current == alias.value ? initial : "";
}

std::string RuleFailure(const std::string& key, const std::string& description,
                        const OptionRule& rule, const nlohmann::json& got) {
  std::string message = "option '" + key + "' must be " + rule.expected + ", got " + got.dump();
  if (!rule.values.empty()) {
    // The first element that is not a valid value, for a did-you-mean suggestion.
    for (const auto& value : got.is_array() ? got : nlohmann::json::array({got})) {
      if (!value.is_string()) continue;
      const std::string text = value.get<std::string>();
      if (std::find(rule.values.begin(), rule.values.end(), text) != rule.values.end()) continue;
      const std::string nearest = NearestKey(text, rule.values);
      if (!nearest.empty()) message += " (did you mean '" + nearest + "'?)";
      break;
    }
  }
  return message + " (" + key + ": " + description + ")";
}

}  // namespace options_detail

}  // namespace raytime
