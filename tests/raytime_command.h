// Runs the raytime binary the way a user does, for the tests that drive it end to end.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>

namespace raytime {

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};

// A JSON file (summary.json, transforms.json) as the tests read it back; discarded (is_discarded)
// when missing or not JSON.
inline nlohmann::json ReadJsonFile(const std::filesystem::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in, nullptr, false);
}

// A copy of the sample scene (data/sample/fountain-P11, Strecha layout) at `to`, for a test that
// changes its files; returns `to`.
inline std::filesystem::path CopySampleScene(const std::filesystem::path& to) {
  std::filesystem::copy(std::filesystem::path(RAYTIME_SOURCE_DIR) / "data/sample/fountain-P11", to,
                        std::filesystem::copy_options::recursive);
  return to;
}

// Runs a shell command line and collects its stdout.
inline CommandResult RunShell(const std::string& command) {
  CommandResult result;
  FILE* pipe = popen(command.c_str(), "r");
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) result.output.append(buffer, n);
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

// Runs `ENVIRONMENT raytime ARGS` from the source directory, so the configs' relative paths
// resolve; output = stdout and stderr.
inline CommandResult RunRaytime(const std::string& args, const std::string& environment = "") {
  return RunShell(std::string("cd ") + RAYTIME_SOURCE_DIR + " && " + environment + " " +
                  RAYTIME_BINARY + " " + args + " 2>&1");
}

// The same with the streams apart: output = stdout only, `stderr_text` = the log.
inline CommandResult RunRaytimeStdout(const std::string& args, std::string* stderr_text) {
  const std::string err = (std::filesystem::temp_directory_path() /
                           ("raytime_stderr_" + std::to_string(::getpid()) + ".txt"))
                              .string();
  const CommandResult result = RunShell(std::string("cd ") + RAYTIME_SOURCE_DIR + " && " +
                                        RAYTIME_BINARY + " " + args + " 2>" + err);
  std::ifstream in(err);
  stderr_text->assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  std::filesystem::remove(err);
  return result;
}

}  // namespace raytime
