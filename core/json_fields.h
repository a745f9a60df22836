// JSON of a record whose static `VisitFields(self, visitor)` lists its fields by name (the keys),
// where a number may be "not reported": a number that is not finite is written as null, and read
// back a number absent or null (or not a number) is NaN; another field absent, null or of the
// wrong type takes its default. For records that rows of a sweep carry from summaries written by
// other runs (evaluate/pose_errors.h's PoseErrorStatistics, report/sweep_row.h): an older
// summary without a field reads as "not reported", not as 0. Records whose every field is always
// set use NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE instead.
#pragma once

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <type_traits>

namespace raytime {

// A number that may be "not reported": null when not finite.
inline nlohmann::json NullIfNonFinite(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

template <class Record>
nlohmann::json FieldsToJson(const Record& record) {
  nlohmann::json json = nlohmann::json::object();
  Record::VisitFields(record, [&](const char* key, const auto& value) {
    if constexpr (std::is_floating_point_v<std::decay_t<decltype(value)>>) {
      json[key] = NullIfNonFinite(value);
    } else {
      json[key] = value;
    }
  });
  return json;
}

template <class Record>
Record FieldsFromJson(const nlohmann::json& json) {
  Record record;
  Record::VisitFields(record, [&](const char* key, auto& value) {
    using Field = std::decay_t<decltype(value)>;
    const auto it = json.find(key);
    const bool present = it != json.end() && !it->is_null();
    if constexpr (std::is_floating_point_v<Field>) {
      value = present && it->is_number() ? it->template get<Field>()
                                         : std::numeric_limits<Field>::quiet_NaN();
    } else if constexpr (std::is_same_v<Field, bool>) {
      value = present && it->is_boolean() ? it->template get<bool>() : Field{};
    } else if constexpr (std::is_arithmetic_v<Field>) {
      value = present && it->is_number() ? it->template get<Field>() : Field{};
    } else {
      value = present && it->is_string() ? it->template get<Field>() : Field{};
    }
  });
  return record;
}

}  // namespace raytime
