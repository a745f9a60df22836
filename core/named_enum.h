// An enumeration that is text wherever it leaves the program: declared once with its names, read
// from options (core/options.h) and written to JSON (summaries, provenance, content hashes) as
// those names, compared inside the program as values.
//
//   enum class Mode { kFast, kExact };
//   constexpr std::array<EnumName<Mode>, 2> EnumNames(Mode) {
//     return {{{Mode::kFast, "fast"}, {Mode::kExact, "exact"}}};
//   }
//
// EnumNames is found by argument-dependent lookup, so it is declared beside the enum, in its
// namespace. The table's order is the order the valid values are listed in (help, errors).
#pragma once

#include <array>
#include <nlohmann/json.hpp>
#include <string>
#include <type_traits>
#include <vector>

#include "core/error.h"

namespace raytime {

template <typename E>
struct EnumName {
  E value;
  const char* name;
};

template <typename T, typename = void>
struct IsNamedEnum : std::false_type {};
template <typename T>
struct IsNamedEnum<T, std::void_t<decltype(EnumNames(std::declval<T>()))>> : std::is_enum<T> {};
template <typename T>
inline constexpr bool kIsNamedEnum = IsNamedEnum<T>::value;

// The name of `value` ("" for a value its table lacks, which is a bug: the table lists them all).
template <typename E>
const char* NameOf(E value) {
  for (const auto& entry : EnumNames(value)) {
    if (entry.value == value) return entry.name;
  }
  return "";
}

// Every name, in the table's order.
template <typename E>
std::vector<std::string> EnumValueNames() {
  std::vector<std::string> names;
  for (const auto& entry : EnumNames(E{})) names.emplace_back(entry.name);
  return names;
}

// The value named `text` into *value; false (and *value unchanged) when no value has that name.
template <typename E>
bool EnumFromName(const std::string& text, E* value) {
  for (const auto& entry : EnumNames(E{})) {
    if (text == entry.name) {
      *value = entry.value;
      return true;
    }
  }
  return false;
}

// JSON of a named enum is its name (nlohmann finds these by argument-dependent lookup; they are
// more specialised than its own, which would write the number).
template <typename E, std::enable_if_t<kIsNamedEnum<E>, int> = 0>
void to_json(nlohmann::json& json, E value) {
  json = NameOf(value);
}

template <typename E, std::enable_if_t<kIsNamedEnum<E>, int> = 0>
void from_json(const nlohmann::json& json, E& value) {
  if (json.is_string() && EnumFromName(json.get_ref<const std::string&>(), &value)) return;
  std::string names;
  for (const std::string& name : EnumValueNames<E>()) names += (names.empty() ? "" : ", ") + name;
  throw InputError("expected one of: " + names + ", got " + json.dump());
}

}  // namespace raytime
