#include "core/process.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace raytime {
namespace {

// A word the shell reads back unchanged: as is when every character is one the shell never
// interprets, else in single quotes.
std::string Quoted(const std::string& s) {
  const auto plain = [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) ||
           (c != '\0' && std::strchr("_-./=:,@%+", c) != nullptr);
  };
  if (!s.empty() && std::all_of(s.begin(), s.end(), plain)) return s;
  std::string quoted = "'";
  for (const char c : s) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// This process's environment plus the defaults whose names it does not set.
std::vector<std::string> ChildEnvironment(const std::vector<std::string>& defaults) {
  std::vector<std::string> env;
  for (char** e = environ; *e != nullptr; ++e) env.emplace_back(*e);
  for (const std::string& entry : defaults) {
    const std::string prefix = entry.substr(0, entry.find('=') + 1);
    bool set = false;
    for (char** e = environ; *e != nullptr && !set; ++e) {
      set = std::strncmp(*e, prefix.c_str(), prefix.size()) == 0;
    }
    if (!set) env.push_back(entry);
  }
  return env;
}

// argv / envp for exec: pointers into `strings`, which must outlive them.
std::vector<char*> NullTerminated(std::vector<std::string>* strings) {
  std::vector<char*> pointers;
  for (std::string& s : *strings) pointers.push_back(s.data());
  pointers.push_back(nullptr);
  return pointers;
}

ProcessStatus StatusFromWait(int status) {
  ProcessStatus out;
  if (WIFEXITED(status)) {
    out.exit_code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    out.signal = WTERMSIG(status);
  }
  return out;
}

}  // namespace

std::string ProcessStatus::Describe() const {
  if (signal != 0) return "was killed by signal " + std::to_string(signal);
  return "exited with status " + std::to_string(exit_code);
}

std::string CommandLine(const std::vector<std::string>& argv) {
  std::string line;
  for (const auto& arg : argv) line += (line.empty() ? "" : " ") + Quoted(arg);
  return line;
}

pid_t StartProcess(const std::vector<std::string>& argv, const ProcessOptions& options) {
  if (argv.empty()) throw std::invalid_argument("StartProcess: no program given");
  std::vector<std::string> args = argv;
  std::vector<std::string> env = ChildEnvironment(options.default_environment);
  const std::vector<char*> arg_pointers = NullTerminated(&args);
  const std::vector<char*> env_pointers = NullTerminated(&env);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  // The output file is opened before the change of directory, so a relative path is the
  // caller's.
  if (!options.output_path.empty()) {
    const int mode = O_WRONLY | O_CREAT | (options.append_output ? O_APPEND : O_TRUNC);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, options.output_path.c_str(), mode,
                                     0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  }
  if (!options.working_dir.empty()) {
    posix_spawn_file_actions_addchdir_np(&actions, options.working_dir.c_str());
  }
  posix_spawnattr_t attributes;
  posix_spawnattr_init(&attributes);
  if (options.new_process_group) {
    posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETPGROUP);
    posix_spawnattr_setpgroup(&attributes, 0);  // 0: a group whose id is the child's pid
  }
  pid_t pid = 0;
  // glibc reports a failed exec or file action here (the child runs vfork-style until exec).
  const int error = posix_spawnp(&pid, arg_pointers[0], &actions, &attributes, arg_pointers.data(),
                                 env_pointers.data());
  posix_spawnattr_destroy(&attributes);
  posix_spawn_file_actions_destroy(&actions);
  if (error != 0) {
    throw std::runtime_error("cannot run '" + CommandLine(argv) + "': " + std::strerror(error));
  }
  return pid;
}

ProcessStatus WaitProcess(pid_t pid) {
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) {
      throw std::runtime_error("waiting for process " + std::to_string(pid) +
                               " failed: " + std::strerror(errno));
    }
  }
  return StatusFromWait(status);
}

bool WaitProcessFor(pid_t pid, double seconds, ProcessStatus* status) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point deadline =
      Clock::now() + std::chrono::duration_cast<Clock::duration>(
                         std::chrono::duration<double>(std::clamp(seconds, 0.0, 1e9)));
  while (true) {
    int raw = 0;
    const pid_t ended = waitpid(pid, &raw, WNOHANG);
    if (ended == pid) {
      *status = StatusFromWait(raw);
      return true;
    }
    if (ended < 0 && errno != EINTR) {
      throw std::runtime_error("waiting for process " + std::to_string(pid) +
                               " failed: " + std::strerror(errno));
    }
    const Clock::time_point now = Clock::now();
    if (now >= deadline) return false;
    std::this_thread::sleep_for(
        std::min<Clock::duration>(deadline - now, std::chrono::milliseconds(50)));
  }
}

FinishedProcess WaitAnyProcess() {
  int status = 0;
  pid_t pid = 0;
  while ((pid = waitpid(-1, &status, 0)) < 0) {
    if (errno != EINTR) {
      throw std::runtime_error(std::string("waiting for a child process failed: ") +
                               std::strerror(errno));
    }
  }
  return {pid, StatusFromWait(status)};
}

bool SignalProcess(pid_t pid, int signal) { return ::kill(pid, signal) == 0; }

bool SignalProcessGroup(pid_t pid, int signal) { return ::kill(-pid, signal) == 0; }

ProcessStatus RunProcess(const std::vector<std::string>& argv, const ProcessOptions& options) {
  return WaitProcess(StartProcess(argv, options));
}

}  // namespace raytime
