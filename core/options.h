// One list of fields per options struct, used for YAML parsing, JSON provenance and `--set`.
//
// An options struct names its fields once, with the YAML key equal to the field name:
//
//   struct FooOptions {
//     double max_error_px = 4.0;  // pixels (paper §4.1)
//     template <class Visitor> void VisitFields(Visitor&& v) { v("max_error_px", max_error_px); }
//   };
//
// Supported field types: bool, int, int64_t, double, std::string and std::vector of int, double
// or std::string. Unknown keys are errors that name the file, the line and the nearest valid key.
#pragma once

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <type_traits>
#include <vector>

#include "core/error.h"

namespace raytime {

// Edit distance, for "did you mean" suggestions.
int EditDistance(const std::string& a, const std::string& b);
// The candidate closest to `key`, or "" when none is plausibly meant (distance > half the key).
std::string NearestKey(const std::string& key, const std::vector<std::string>& candidates);
// "unknown key 'x' in <what> (did you mean 'y'?); valid keys: a, b, c". `noun` replaces "key".
std::string UnknownKeyMessage(const std::string& what, const std::string& key,
                              const std::vector<std::string>& candidates,
                              const std::string& noun = "key");

// "name (line N)" context for YAML nodes; line is 1-based, 0 when the node has no mark.
int YamlLine(const YAML::Node& node);

template <typename T>
const char* TypeName() {
  if constexpr (std::is_same_v<T, bool>) return "a boolean";
  if constexpr (std::is_same_v<T, int> || std::is_same_v<T, int64_t>) return "an integer";
  if constexpr (std::is_same_v<T, double>) return "a number";
  if constexpr (std::is_same_v<T, std::string>) return "a string";
  if constexpr (std::is_same_v<T, std::vector<int>>) return "a list of integers";
  if constexpr (std::is_same_v<T, std::vector<double>>) return "a list of numbers";
  if constexpr (std::is_same_v<T, std::vector<std::string>>) return "a list of strings";
  return "a value";
}

// Converts one YAML node into a field, with a located error on a type mismatch.
template <typename T>
void ReadYamlField(const YAML::Node& node, T& field, const std::string& path,
                   const std::string& key) {
  try {
    field = node.as<T>();
  } catch (const YAML::Exception&) {
    ThrowInput(path, YamlLine(node),
               "option '" + key + "' must be " + TypeName<T>() + ", got '" + YAML::Dump(node) +
                   "'");
  }
}

namespace options_detail {
struct KeyCollector {
  std::vector<std::string> keys;
  template <typename T>
  void operator()(const char* key, T&) {
    keys.emplace_back(key);
  }
};
struct YamlReader {
  const YAML::Node& map;
  const std::string& path;
  template <typename T>
  void operator()(const char* key, T& field) {
    const YAML::Node child = map[key];
    if (child) ReadYamlField(child, field, path, key);
  }
};
struct JsonWriter {
  nlohmann::json& out;
  template <typename T>
  void operator()(const char* key, T& field) {
    out[key] = field;
  }
};
struct JsonReader {
  const nlohmann::json& in;
  template <typename T>
  void operator()(const char* key, T& field) {
    if (in.contains(key)) field = in.at(key).get<T>();
  }
};
}  // namespace options_detail

template <typename Options>
std::vector<std::string> OptionKeys(Options& options) {
  options_detail::KeyCollector collector;
  options.VisitFields(collector);
  return collector.keys;
}

// Applies a YAML mapping onto `options`; keys absent from the mapping keep their defaults.
// `path` names the file for error messages; `what` names the section ("stage 'prior'").
template <typename Options>
void ApplyYaml(const YAML::Node& map, Options& options, const std::string& path,
               const std::string& what) {
  if (!map || map.IsNull()) return;
  if (!map.IsMap()) ThrowInput(path, YamlLine(map), what + " options must be a mapping");
  const std::vector<std::string> keys = OptionKeys(options);
  for (const auto& entry : map) {
    if (entry.first.IsMap() || entry.first.IsSequence()) {
      ThrowInput(path, YamlLine(entry.first), what + ": an option key must be a name");
    }
    const std::string key = entry.first.as<std::string>();
    if (std::find(keys.begin(), keys.end(), key) == keys.end()) {
      ThrowInput(path, YamlLine(entry.first), UnknownKeyMessage(what, key, keys));
    }
  }
  options_detail::YamlReader reader{map, path};
  options.VisitFields(reader);
}

template <typename Options>
nlohmann::json OptionsToJson(Options& options) {
  nlohmann::json out = nlohmann::json::object();
  options_detail::JsonWriter writer{out};
  options.VisitFields(writer);
  return out;
}

template <typename Options>
void OptionsFromJson(const nlohmann::json& in, Options& options) {
  options_detail::JsonReader reader{in};
  options.VisitFields(reader);
}

}  // namespace raytime
