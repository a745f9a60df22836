// Runs the raytime binary the way a user does, for the tests that drive it end to end.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace raytime {

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};

// Runs `ENVIRONMENT raytime ARGS` from the source directory, so the configs' relative paths
// resolve.
inline CommandResult RunRaytime(const std::string& args, const std::string& environment = "") {
  const std::string command = std::string("cd ") + RAYTIME_SOURCE_DIR + " && " + environment + " " +
                              RAYTIME_BINARY + " " + args + " 2>&1";
  CommandResult result;
  FILE* pipe = popen(command.c_str(), "r");
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) result.output.append(buffer, n);
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

}  // namespace raytime
