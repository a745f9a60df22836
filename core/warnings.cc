#include "core/warnings.h"

#include "core/error.h"

namespace raytime {

namespace {

// Every string (and object key) of `value` with invalid UTF-8 escaped (EscapeInvalidUtf8).
nlohmann::json EscapeStrings(const nlohmann::json& value) {
  if (value.is_string()) return EscapeInvalidUtf8(value.get<std::string>());
  if (value.is_array()) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& element : value) out.push_back(EscapeStrings(element));
    return out;
  }
  if (value.is_object()) {
    nlohmann::json out = nlohmann::json::object();
    for (const auto& [key, element] : value.items()) {
      out[EscapeInvalidUtf8(key)] = EscapeStrings(element);
    }
    return out;
  }
  return value;
}

}  // namespace

// Messages, names and details may quote file names and contents that are not UTF-8
// (EscapeInvalidUtf8); summary.json must still be written.
nlohmann::json Warning::ToJson() const {
  nlohmann::json out = {{"code", code}, {"message", EscapeInvalidUtf8(message)}};
  if (!images.empty()) {
    out["images"] = nlohmann::json::array();
    for (const std::string& image : images) out["images"].push_back(EscapeInvalidUtf8(image));
  }
  if (!pairs.empty()) {
    out["pairs"] = nlohmann::json::array();
    for (const auto& [a, b] : pairs) {
      out["pairs"].push_back({EscapeInvalidUtf8(a), EscapeInvalidUtf8(b)});
    }
  }
  if (!details.empty()) out["details"] = EscapeStrings(details);
  return out;
}

Warning Warning::FromJson(const nlohmann::json& json) {
  Warning warning;
  warning.code = json.value("code", "");
  warning.message = json.value("message", "");
  if (json.contains("images")) warning.images = json.at("images").get<std::vector<std::string>>();
  if (json.contains("pairs")) {
    for (const auto& pair : json.at("pairs")) {
      warning.pairs.emplace_back(pair.at(0).get<std::string>(), pair.at(1).get<std::string>());
    }
  }
  if (json.contains("details")) warning.details = json.at("details");
  return warning;
}

nlohmann::json WarningsToJson(const Warnings& warnings) {
  nlohmann::json out = nlohmann::json::array();
  for (const Warning& warning : warnings) out.push_back(warning.ToJson());
  return out;
}

}  // namespace raytime
