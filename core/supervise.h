// A crash that cannot be caught is still recorded: the `raytime` command runs its work in a child
// process and waits for it. A child killed by a signal (SIGSEGV in a library, SIGABRT, the
// out-of-memory killer's SIGKILL) or ending without recording how (libgomp exits with status 1
// when it cannot start a thread) leaves its record at "running"; the waiting parent, which did
// nothing but wait, finishes it (cli/main.cc).
//
//   if (const std::optional<SupervisedEnd> end = ForkSupervised()) {
//     return RecordHowItEnded(*end);  // the parent, once the child has ended
//   }
//   ...  // the child: the work
//
// Call it before any thread starts (a fork copies only the calling thread). The parent forwards
// SIGINT, SIGTERM, SIGHUP and SIGQUIT to the child; the child gets SIGTERM when the parent dies.
// When this process's stderr is not a terminal, the child's stderr passes through the parent,
// which keeps its last lines (a library's last words before it ended the process).
// RAYTIME_UNSUPERVISED=1 in the environment runs the work in this process (for a debugger).
#pragma once

#include <sys/types.h>

#include <optional>
#include <string>

#include "core/process.h"

namespace raytime {

struct SupervisedEnd {
  pid_t child = 0;
  ProcessStatus status;
  std::string stderr_tail;  // the child's last stderr lines (empty when it went to a terminal)
};

// Returns std::nullopt in the child (and when supervision is off or impossible: the work then
// runs in this process), and how the child ended in the parent.
std::optional<SupervisedEnd> ForkSupervised();

// "signal 11 (Segmentation fault)".
std::string DescribeSignal(int signal);

}  // namespace raytime
