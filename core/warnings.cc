#include "core/warnings.h"

namespace raytime {

nlohmann::json Warning::ToJson() const {
  nlohmann::json out = {{"code", code}, {"message", message}};
  if (!images.empty()) out["images"] = images;
  if (!pairs.empty()) {
    out["pairs"] = nlohmann::json::array();
    for (const auto& [a, b] : pairs) out["pairs"].push_back({a, b});
  }
  if (!details.empty()) out["details"] = details;
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
