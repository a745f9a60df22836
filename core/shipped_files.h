// Where the files raytime ships beside its binary are found at run time: the refine presets
// (configs/presets) and the campaign plot script (scripts/). An installed binary runs on a machine
// without the source tree it was built from, so the lookup is, in order:
//   1. the environment variable the caller names (RAYTIME_PRESET_DIR, RAYTIME_SCRIPT_DIR), alone
//      when set: a user who sets it means that folder;
//   2. the installed package's data folder relative to the executable
//      (<bin>/../share/raytime/<relative>, `cmake --install` and the .deb);
//   3. the source tree the binary was built from (a build tree's binary, the tests).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace raytime {

struct ShippedDirectory {
  std::filesystem::path path;                   // the first candidate that is a folder; else empty
  std::vector<std::filesystem::path> searched;  // every candidate, in order, for a message
  std::string env_variable;
  bool from_env = false;  // the environment variable was set (and is the only candidate)
  // Where it looked and what overrides it, for an error or a warning that says what to do:
  // "A, B (or set ENV)", or "A (from ENV)".
  std::string Searched() const;
};

// `relative` is the folder's path in the source tree and under share/raytime/ alike
// ("configs/presets", "scripts").
ShippedDirectory FindShippedDirectory(const char* env_variable, const std::string& relative);

}  // namespace raytime
