// One declaration per option: key, field, one-line description and the rules its value obeys.
//
// An options struct names its fields once, with the YAML key equal to the field name:
//
//   struct FooOptions {
//     double max_error_px = 4.0;
//     std::string mode = "fast";
//     template <class Visitor>
//     void VisitFields(Visitor&& v) {
//       v("max_error_px", max_error_px, "Inlier threshold, pixels (paper §4.1)", Positive());
//       v("mode", mode, "How to do it", OneOf({"fast", "exact"}));
//     }
//     // Optional: constraints between fields.
//     void CheckRelations(const Requirement& require) const {
//       require(mode != "exact" || max_error_px < 8, "mode 'exact' needs max_error_px < 8");
//     }
//   };
//
// From that list come YAML parsing (unknown keys: file, line and the nearest valid key), JSON
// provenance, the stage command lines with their --help text, content hashes and validation
// (ValidateOptions: every rule and relation, one InputError naming the option, its description
// and what was expected). Supported field types: bool, int, int64_t, double, std::string,
// std::vector of int, double or std::string, and an enumeration with a name table
// (core/named_enum.h: read and written as its names, "one of: ..." in its help and errors, no
// OneOf rule needed). Rules on a list apply to each element.
//
// A key that was replaced by a value of an enumeration stays accepted for a while: the struct
// lists it in `static std::vector<OptionAlias> DeprecatedAliases()` (OptionAlias below).
#pragma once

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <type_traits>
#include <vector>

#include "core/error.h"
#include "core/named_enum.h"
#include "core/user_paths.h"

namespace raytime {

// Edit distance, for "did you mean" suggestions.
int EditDistance(const std::string& a, const std::string& b);
// The candidate closest to `key`, or "" when none is plausibly meant (distance > half the key).
std::string NearestKey(const std::string& key, const std::vector<std::string>& candidates);
// "unknown key 'x' in <what> (did you mean 'y'?); valid keys: a, b, c". `noun` replaces "key".
std::string UnknownKeyMessage(const std::string& what, const std::string& key,
                              const std::vector<std::string>& candidates,
                              const std::string& noun = "key");

// 1-based line of a YAML node, 0 when the node has no mark.
int YamlLine(const YAML::Node& node);

// YAML::LoadFile of a file whose mappings must not repeat a key: yaml-cpp keeps both and a lookup
// finds the first, so a repeated key would be silently ignored. InputError naming the file and
// line (a syntax error, or the second occurrence of a key with the first one's line).
YAML::Node LoadYamlFile(const std::string& path);

// InputError at `path`:`line` unless `text` is UTF-8: options, names and paths from YAML end up
// in JSON (provenance, content hashes, summary.json), which holds nothing else. The message
// names the offending byte without repeating it.
void RequireUtf8(const std::string& text, const std::string& path, int line,
                 const std::string& what);

// A rule on an option's value: what it expects, in words ("positive", "one of a, b"), and the
// test for numbers, for strings and for a list's length (those a rule does not test pass).
// Numeric rules also refuse NaN and infinities: no option means anything at either.
struct OptionRule {
  std::string expected;
  std::function<bool(double)> number;
  std::function<bool(const std::string&)> text;
  std::function<bool(size_t)> list_size;
  std::vector<std::string> values;  // the valid values of an enumeration (OneOf)
};

OptionRule Positive();           // > 0
OptionRule NonNegative();        // >= 0
OptionRule AtLeast(double min);  // >= min
OptionRule Above(double min);    // > min
OptionRule AtMost(double max);   // <= max
OptionRule Below(double max);    // < max
OptionRule OneOf(std::vector<std::string> values);
OptionRule NonEmpty();  // a string that is not "", a list with elements

// Constraints between fields: `require(condition, message)` fails validation with `message`.
using Requirement = std::function<void(bool, const std::string&)>;

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

// Short type tag for command-line help: BOOL, INT, NUMBER, TEXT (lists: of their elements; an
// enumeration is written as text).
template <typename T>
const char* TypeTag() {
  if constexpr (kIsNamedEnum<T>) return "TEXT";
  if constexpr (std::is_same_v<T, bool>) return "BOOL";
  if constexpr (std::is_same_v<T, int> || std::is_same_v<T, int64_t>) return "INT";
  if constexpr (std::is_same_v<T, double>) return "NUMBER";
  if constexpr (std::is_same_v<T, std::string>) return "TEXT";
  if constexpr (std::is_same_v<T, std::vector<int>>) return "INT";
  if constexpr (std::is_same_v<T, std::vector<double>>) return "NUMBER";
  if constexpr (std::is_same_v<T, std::vector<std::string>>) return "TEXT";
  return "VALUE";
}

template <typename T>
struct IsVector : std::false_type {};
template <typename T>
struct IsVector<std::vector<T>> : std::true_type {};

// Converts one YAML node into a field, with a located error on a type mismatch. Booleans also
// accept 1 and 0, as command lines write them. A text option given no value (`key:`, `~`, `--set
// stage.key=`) is the empty text, which the options' rules then refuse where it must not be: as
// yaml-cpp reads it, it was the text "null" (a prior.path "null", found only after hours of
// matching).
template <typename T>
void ReadYamlField(const YAML::Node& node, T& field, const std::string& path,
                   const std::string& key) {
  if constexpr (std::is_same_v<T, std::string>) {
    if (node.IsNull()) {
      field.clear();
      return;
    }
  }
  try {
    if constexpr (std::is_same_v<T, bool>) {
      if (node.IsScalar() && (node.Scalar() == "1" || node.Scalar() == "0")) {
        field = node.Scalar() == "1";
        return;
      }
    }
    field = node.as<T>();
  } catch (const YAML::Exception&) {
    ThrowInput(
        path, YamlLine(node),
        "option '" + key + "' must be " + TypeName<T>() + ", got '" + YAML::Dump(node) + "'");
  }
  // yaml-cpp reads .nan and .inf as numbers; no option means either (a NaN fails every rule
  // quietly, and JSON would report it as null).
  if constexpr (std::is_same_v<T, double> || std::is_same_v<T, std::vector<double>>) {
    bool finite = true;
    if constexpr (std::is_same_v<T, double>) {
      finite = std::isfinite(field);
    } else {
      for (const double element : field) finite = finite && std::isfinite(element);
    }
    if (!finite) {
      ThrowInput(path, YamlLine(node),
                 "option '" + key + "' must be " +
                     (IsVector<T>::value ? "a list of finite numbers" : "a finite number") +
                     ", got '" + YAML::Dump(node) + "'");
    }
  }
  if constexpr (std::is_same_v<T, std::string>) {
    RequireUtf8(field, path, YamlLine(node), "option '" + key + "'");
    // The text options that may start with a tilde are paths and commands: expanded as a shell
    // expands a word's leading tilde (a YAML file or a --set is no shell).
    field = ExpandUser(field);
  } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
    for (const std::string& element : field) {
      RequireUtf8(element, path, YamlLine(node), "option '" + key + "'");
    }
  }
}

// Everything declared about one option, for help text, documentation tests and error messages.
struct OptionDoc {
  std::string key;
  std::string type;           // TypeTag
  std::string default_value;  // as JSON text
  std::string description;
  std::vector<std::string> expected;  // the rules' words
  std::vector<std::string> values;    // of an enumeration
  bool is_list = false;
  bool is_bool = false;

  // "description; positive; one of: a, b" for --help.
  std::string HelpText() const;
};

// A deprecated boolean key that a value of an enumeration option replaced (`staged: true` is now
// `recipe: staged`). `old_key: true` sets new_key to `value`, and is refused where new_key already
// holds a value other than its default and `value` (by an earlier alias or a preset: two recipes
// at once); `old_key: false` puts new_key back to its default where it holds `value`, and changes
// nothing otherwise (the key it stands for was off). ApplyYaml applies them before the struct's
// own keys, so a new key given beside its old one wins, and warns once per alias and value.
struct OptionAlias {
  std::string old_key;
  std::string new_key;
  std::string value;
};

namespace options_detail {

// The text `old_key: on` gives alias.new_key, which holds `current` (`initial` by default), or ""
// when it changes nothing; a spdlog warning naming the new key and value (once per process and
// message: a pipeline's options are read several times). InputError at `path`:`line` on a conflict.
std::string AliasedValue(const OptionAlias& alias, bool on, const std::string& current,
                         const std::string& initial, const std::string& path, int line,
                         const std::string& what);

// "option 'key' must be <expected>, got <value> [(did you mean 'x'?)] (key: description)".
std::string RuleFailure(const std::string& key, const std::string& description,
                        const OptionRule& rule, const nlohmann::json& got);

// An enumeration's value from its name in `node`; a text that names none is an InputError at
// `path` and the node's line, the message the OneOf rule gives: "<what>: option 'key' must be one
// of: a, b, got "x" (did you mean 'y'?) (key: description)".
template <typename E>
void ReadYamlEnum(const YAML::Node& node, E& field, const std::string& path,
                  const std::string& what, const std::string& key, const std::string& description) {
  const std::string text = node.IsScalar() ? node.Scalar() : node.IsNull() ? "" : YAML::Dump(node);
  if (EnumFromName(text, &field)) return;
  RequireUtf8(text, path, YamlLine(node), "option '" + key + "'");
  ThrowInput(path, YamlLine(node),
             what + ": " +
                 RuleFailure(key, description, OneOf(EnumValueNames<E>()), nlohmann::json(text)));
}

// The first rule `value` breaks, or nullptr.
template <typename T>
const OptionRule* BrokenRule(const T& value, const std::vector<const OptionRule*>& rules) {
  for (const OptionRule* rule : rules) {
    if constexpr (IsVector<T>::value) {
      if (rule->list_size && !rule->list_size(value.size())) return rule;
      for (const auto& element : value) {
        if (BrokenRule(element, {rule}) != nullptr) return rule;
      }
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (rule->text && !rule->text(value)) return rule;
    } else if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
      if (rule->number && !rule->number(static_cast<double>(value))) return rule;
    }
  }
  return nullptr;
}

struct KeyCollector {
  std::vector<std::string> keys;
  template <typename T, typename... Rules>
  void operator()(const char* key, T&, const char*, const Rules&...) {
    keys.emplace_back(key);
  }
};
struct YamlReader {
  const YAML::Node& map;
  const std::string& path;
  const std::string& what;
  template <typename T, typename... Rules>
  void operator()(const char* key, T& field, const char* description, const Rules&...) {
    const YAML::Node child = map[key];
    if (!child) return;
    if constexpr (kIsNamedEnum<T>) {
      ReadYamlEnum(child, field, path, what, key, description);
    } else {
      ReadYamlField(child, field, path, key);
    }
  }
};
struct JsonWriter {
  nlohmann::json& out;
  template <typename T, typename... Rules>
  void operator()(const char* key, T& field, const char*, const Rules&...) {
    out[key] = field;
  }
};
struct JsonReader {
  const nlohmann::json& in;
  template <typename T, typename... Rules>
  void operator()(const char* key, T& field, const char*, const Rules&...) {
    if (in.contains(key)) field = in.at(key).get<T>();
  }
};
struct Validator {
  std::vector<std::string>& errors;
  template <typename T, typename... Rules>
  void operator()(const char* key, T& field, const char* description, const Rules&... rules) {
    const OptionRule* broken = BrokenRule(field, {&rules...});
    if (broken != nullptr) {
      errors.push_back(RuleFailure(key, description, *broken, nlohmann::json(field)));
    }
  }
};
struct DocCollector {
  std::vector<OptionDoc>& docs;
  template <typename T, typename... Rules>
  void operator()(const char* key, T& field, const char* description, const Rules&... rules) {
    OptionDoc doc;
    doc.key = key;
    doc.type = TypeTag<T>();
    doc.default_value = nlohmann::json(field).dump();
    doc.description = description;
    doc.is_list = IsVector<T>::value;
    doc.is_bool = std::is_same_v<T, bool>;
    std::vector<OptionRule> implied;  // an enumeration's names, as OneOf lists them
    if constexpr (kIsNamedEnum<T>) implied.push_back(OneOf(EnumValueNames<T>()));
    for (const OptionRule* rule : std::initializer_list<const OptionRule*>{&rules...}) {
      implied.push_back(*rule);
    }
    for (const OptionRule& rule : implied) {
      doc.expected.push_back(rule.expected);
      doc.values.insert(doc.values.end(), rule.values.begin(), rule.values.end());
    }
    docs.push_back(std::move(doc));
  }
};

// Checks the rules of the fields `map` gives (relations are left for ValidateOptions, once every
// value is in place); the first broken one is an InputError at `path` and the value's line.
struct GivenFieldValidator {
  const YAML::Node& map;
  const std::string& path;
  const std::string& what;
  template <typename T, typename... Rules>
  void operator()(const char* key, T& field, const char* description, const Rules&... rules) {
    if (!map[key]) return;
    const OptionRule* broken = BrokenRule(field, {&rules...});
    if (broken != nullptr) {
      ThrowInput(path, YamlLine(map[key]),
                 what + ": " + RuleFailure(key, description, *broken, nlohmann::json(field)));
    }
  }
};

template <typename Options, typename = void>
struct HasAliases : std::false_type {};
template <typename Options>
struct HasAliases<Options, std::void_t<decltype(Options::DeprecatedAliases())>> : std::true_type {};

template <typename Options, typename = void>
struct HasRelations : std::false_type {};
template <typename Options>
struct HasRelations<Options, std::void_t<decltype(std::declval<const Options&>().CheckRelations(
                                 std::declval<const Requirement&>()))>> : std::true_type {};

}  // namespace options_detail

template <typename Options>
std::vector<std::string> OptionKeys(Options& options) {
  options_detail::KeyCollector collector;
  options.VisitFields(collector);
  return collector.keys;
}

// Every option's declaration, in VisitFields order, with defaults taken from `options`.
template <typename Options>
std::vector<OptionDoc> OptionDocs(Options& options) {
  std::vector<OptionDoc> docs;
  options_detail::DocCollector collector{docs};
  options.VisitFields(collector);
  return docs;
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

// The struct's deprecated keys (OptionAlias), none where it declares none.
template <typename Options>
std::vector<OptionAlias> DeprecatedAliases() {
  if constexpr (options_detail::HasAliases<Options>::value) {
    return Options::DeprecatedAliases();
  } else {
    return {};
  }
}

namespace options_detail {

// The deprecated keys `map` gives, applied onto `options` as their new keys (OptionAlias).
template <typename Options>
void ApplyAliases(const YAML::Node& map, Options& options, const std::string& path,
                  const std::string& what) {
  for (const OptionAlias& alias : DeprecatedAliases<Options>()) {
    const YAML::Node given = map[alias.old_key];
    if (!given) continue;
    bool on = false;
    ReadYamlField(given, on, path, alias.old_key);
    Options initial;
    const std::string value = AliasedValue(
        alias, on, OptionsToJson(options).at(alias.new_key).template get<std::string>(),
        OptionsToJson(initial).at(alias.new_key).template get<std::string>(), path, YamlLine(given),
        what);
    if (value.empty()) continue;
    YAML::Node set(YAML::NodeType::Map);
    set[alias.new_key] = value;
    YamlReader reader{set, path, what};
    options.VisitFields(reader);
  }
}

}  // namespace options_detail

// Applies a YAML mapping onto `options`; keys absent from the mapping keep their values. Checks
// keys and value types only (and an enumeration's names): ValidateOptions checks the values once
// all of them are in place. `path` names the file for error messages; `what` names the section
// ("stage 'prior'"). Deprecated keys (OptionAlias) are applied first, with a warning.
template <typename Options>
void ApplyYaml(const YAML::Node& map, Options& options, const std::string& path,
               const std::string& what) {
  if (!map || map.IsNull()) return;
  if (!map.IsMap()) ThrowInput(path, YamlLine(map), what + " options must be a mapping");
  const std::vector<std::string> keys = OptionKeys(options);
  const std::vector<OptionAlias> aliases = DeprecatedAliases<Options>();
  for (const auto& entry : map) {
    if (entry.first.IsMap() || entry.first.IsSequence()) {
      ThrowInput(path, YamlLine(entry.first), what + ": an option key must be a name");
    }
    const std::string key = entry.first.as<std::string>();
    const bool deprecated = std::any_of(aliases.begin(), aliases.end(),
                                        [&](const OptionAlias& a) { return a.old_key == key; });
    if (!deprecated && std::find(keys.begin(), keys.end(), key) == keys.end()) {
      ThrowInput(path, YamlLine(entry.first), UnknownKeyMessage(what, key, keys));
    }
  }
  options_detail::ApplyAliases(map, options, path, what);
  options_detail::YamlReader reader{map, path, what};
  options.VisitFields(reader);
}

// Checks the rules of the fields `map` sets in `options` (after ApplyYaml of the same map): a
// value out of range is blamed on where it was given (a --set, a sweep value, a YAML line) as
// soon as it arrives, before anything runs.
template <typename Options>
void ValidateGivenFields(const YAML::Node& map, Options& options, const std::string& path,
                         const std::string& what) {
  if (!map || !map.IsMap()) return;
  options_detail::GivenFieldValidator validator{map, path, what};
  options.VisitFields(validator);
}

// Checks every field's rules and the struct's relations; one InputError listing every problem,
// each "<what>: option 'key' must be <expected>, got <value> (<description>)".
template <typename Options>
void ValidateOptions(const Options& options, const std::string& what) {
  std::vector<std::string> errors;
  Options& fields = const_cast<Options&>(options);  // the visitors of VisitFields only read here
  options_detail::Validator validator{errors};
  fields.VisitFields(validator);
  if constexpr (options_detail::HasRelations<Options>::value) {
    options.CheckRelations([&](bool ok, const std::string& message) {
      if (!ok) errors.push_back(message);
    });
  }
  if (errors.empty()) return;
  std::string message;
  for (const auto& error : errors) message += (message.empty() ? "" : "; ") + what + ": " + error;
  throw InputError(message);
}

}  // namespace raytime
