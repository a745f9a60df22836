// Runs the real COLMAP 3.8 binary for the tests that compare against it (label colmap).
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "core/process.h"

namespace raytime {

// The full path of `program` in PATH, "" when it is not there (a test says why it cannot run).
inline std::string FindOnPath(const std::string& program) {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "");
  for (std::string dir; std::getline(dirs, dir, ':');) {
    const std::filesystem::path candidate =
        std::filesystem::path(dir.empty() ? "." : dir) / program;
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return "";
}

// `colmap ARGS` with stdout and stderr in `log` (truncated first). COLMAP links Qt; without a
// display its platform plugin must be the offscreen one.
inline ProcessStatus RunColmap(const std::string& colmap, const std::vector<std::string>& args,
                               const std::string& log) {
  std::vector<std::string> argv = {colmap};
  argv.insert(argv.end(), args.begin(), args.end());
  ProcessOptions options;
  options.output_path = log;
  options.append_output = false;
  options.default_environment = {"QT_QPA_PLATFORM=offscreen"};
  return RunProcess(argv, options);
}

}  // namespace raytime
