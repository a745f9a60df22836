// How a failure is told to the user: which class of outcome it is (the exit status of the
// `raytime` command, summary.json's "cause") and a message that names the cause and what to
// change. Out of memory, out of threads, out of file descriptors and out of disk space come from
// deep inside libraries (std::bad_alloc, OpenCV's "Insufficient memory", TBB's "pthread_create
// has failed", errno) and would otherwise reach the user as a bare library message.
//
// Exit statuses (README "Exit statuses"): 0 the run finished (also with warnings), 1 a stage
// failed, 2 the input or the command line is wrong, 3 a resource ran out (memory, threads, open
// files, disk space), 4 the process crashed (a signal, or it ended without recording how),
// 128 + N interrupted by signal N (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP).
#pragma once

#include <exception>
#include <string>

namespace raytime {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailed = 1;
inline constexpr int kExitInput = 2;
inline constexpr int kExitResource = 3;
inline constexpr int kExitCrashed = 4;

struct FailureDescription {
  // "input", "memory", "threads", "open_files", "disk_space" or "error".
  std::string cause;
  std::string message;  // the error, and for a resource what to change
  int exit_code = kExitFailed;
};

// The class and message of an exception that ended a command.
FailureDescription DescribeFailure(const std::exception& error);

// The class of a resource failure a library printed before it ended the process itself (libgomp
// exits with status 1 when it cannot start a thread): "memory", "threads", "open_files",
// "disk_space", or "" when `text` names none.
std::string ResourceNamedIn(const std::string& text);

// What to change for a resource: the limit in force (ulimit) and the options that use less.
std::string ResourceAdvice(const std::string& cause);

// Raises this process's soft limit on open files to its hard limit (a shell's default soft limit
// is 1024 where the hard one is often far higher).
void RaiseOpenFileLimit();

}  // namespace raytime
