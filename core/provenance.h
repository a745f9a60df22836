// Who wrote a result, with which options, when (SPEC: provenance attributes; stored on every
// pose set, /features and /matches, docs/hdf5_schema.md).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace raytime {

struct Provenance {
  std::string stage;            // e.g. "prior", "refine"
  nlohmann::json options;       // the stage's options as written by OptionsToJson
  std::string created_utc;      // ISO 8601, filled by the writer when empty
  std::string raytime_version;  // filled by the writer when empty
};

}  // namespace raytime
