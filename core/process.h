// Child processes: COLMAP for the classical control, the campaign report's plot script, a sweep's
// runs of raytime itself. A child gets its arguments, optionally a working directory and extra
// environment, stdin from /dev/null, and stdout and stderr either inherited or sent to one file.
// Starting and waiting are separate so that a caller can keep several children running.
//
//   ProcessOptions options;
//   options.output_path = "work/colmap.log";
//   const ProcessStatus status = RunProcess({"colmap", "mapper", ...}, options);
//   if (!status.Succeeded()) throw std::runtime_error("mapper " + status.Describe());
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace raytime {

struct ProcessOptions {
  std::string working_dir;  // "" keeps this process's working directory
  // Where the child's stdout and stderr go: this process's when empty, else this file (created
  // when missing; relative to this process's working directory).
  std::string output_path;
  bool append_output = true;  // false truncates output_path first
  // NAME=VALUE entries added to the child's environment unless this process's environment
  // already sets NAME (a default the user can override); the rest is inherited.
  std::vector<std::string> default_environment;
  // The child leads a new process group (its id = the child's pid), so SignalProcessGroup reaches
  // whatever it starts (a shell's commands, a trainer's workers) and a terminal's Ctrl-C does not:
  // the caller decides when it stops.
  bool new_process_group = false;
};

// How a child ended: its exit code, or the signal that killed it.
struct ProcessStatus {
  int exit_code = -1;  // -1 when killed by a signal
  int signal = 0;      // 0 when it exited
  bool Succeeded() const { return signal == 0 && exit_code == 0; }
  // "exited with status 3" or "was killed by signal 9".
  std::string Describe() const;
};

// The arguments as one shell-quoted line (each word read back unchanged by a POSIX shell), for
// logs, error messages and generated scripts.
std::string CommandLine(const std::vector<std::string>& argv);

// Starts argv[0] (looked up in PATH when it has no '/') with `argv` and returns its process id
// without waiting. Throws std::runtime_error "cannot run '<command line>': <reason>" when the
// program cannot be started (not found, not executable, output file or working directory
// unusable).
pid_t StartProcess(const std::vector<std::string>& argv, const ProcessOptions& options = {});

// Blocks until child `pid` ends.
ProcessStatus WaitProcess(pid_t pid);

// Waits at most `seconds` for child `pid`: true with `status` set when it ended, false when it is
// still running (polls every 50 ms, so long children cost nothing while they run; at most 1e9 s).
bool WaitProcessFor(pid_t pid, double seconds, ProcessStatus* status);

// Blocks until any child of this process ends; throws std::runtime_error when there is none.
struct FinishedProcess {
  pid_t pid = 0;
  ProcessStatus status;
};
FinishedProcess WaitAnyProcess();

// Sends `signal` (e.g. SIGTERM) to child `pid`; false when there is no such process.
bool SignalProcess(pid_t pid, int signal);
// Sends `signal` to every process of the group child `pid` leads (new_process_group); false when
// the group has no process left.
bool SignalProcessGroup(pid_t pid, int signal);

// StartProcess, then WaitProcess.
ProcessStatus RunProcess(const std::vector<std::string>& argv, const ProcessOptions& options = {});

}  // namespace raytime
