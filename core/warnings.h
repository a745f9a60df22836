// Warnings: results that are returned but deserve a second look, reported with a stable code so
// that people, scripts and campaign reports can act on them. A stage's summary carries its
// warnings under "warnings"; the pipeline collects them into summary.json's top-level list and
// sets status "ok_with_warnings" (never a silent wrong result: brief, "Two rules").
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

namespace raytime {

struct Warning {
  // Stable identifier, snake_case: "unmatched_cameras", "disconnected_graph", "missing_prior",
  // "missing_frames", "weak_bootstrap", "skew_ignored", ... (README "Warnings" lists them).
  std::string code;
  std::string message;                                     // one sentence for people
  std::vector<std::string> images;                         // image names concerned
  std::vector<std::pair<std::string, std::string>> pairs;  // image-name pairs concerned
  nlohmann::json details = nlohmann::json::object();       // the numbers behind the verdict

  nlohmann::json ToJson() const;
  static Warning FromJson(const nlohmann::json& json);
};

// ToJson / FromJson for nlohmann's conversions (a summary struct holding Warnings).
inline void to_json(nlohmann::json& json, const Warning& warning) { json = warning.ToJson(); }
inline void from_json(const nlohmann::json& json, Warning& warning) {
  warning = Warning::FromJson(json);
}

using Warnings = std::vector<Warning>;

nlohmann::json WarningsToJson(const Warnings& warnings);

}  // namespace raytime
