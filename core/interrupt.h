// Clean ends on SIGINT, SIGTERM and SIGHUP (the terminal closed). A signal handler only writes
// the signal number into a pipe; a watcher thread reads it, runs the registered actions (newest
// first: e.g. stop child processes, write summary.json with status "interrupted", remove this
// process's temporary files) and exits with 128 + the signal (130 for Ctrl-C, 143 for kill).
// Nothing runs inside the handler itself, so the actions may allocate, lock and write files.
//
// A program that must not end with the signal (the Python module, python/: the interpreter takes
// Ctrl-C itself) calls RequestStop instead: the same actions run, nothing exits, and the work ends
// at its next StopPoint by throwing StopRequested.
#pragma once

#include <functional>

namespace raytime {

// Installs the handlers and starts the watcher; call once at the start of main. Children started
// later get the default dispositions back when they exec.
void InstallInterruptHandler();

// True once a signal has been taken (the watcher is running the actions and will exit the
// process) or a stop was requested.
bool Interrupting();
// For a thread whose work failed because of the interruption (a child it waited for was stopped):
// waits for the watcher to end the process rather than racing it with a second exit status; after
// RequestStop, throws StopRequested.
[[noreturn]] void AwaitInterruptExit();

// Thrown at a StopPoint once a stop was requested. Not a std::exception, so that no handler that
// turns a failure into a result (a stage that does not stop the run, a solve that returns the
// prior) takes it for a failure: it ends the work.
struct StopRequested {};

// Runs the registered actions (newest first, with `signal`) and removes this process's pending
// temporary files, as the watcher does, without exiting: the work stops at its next StopPoint.
void RequestStop(int signal);
// Throws StopRequested once RequestStop was called: where long work can stop cleanly (a progress
// update, between stages, an iteration of a solve). Without RequestStop (the CLI) it does nothing.
void StopPoint();
bool StopWasRequested();
// Forgets a request whose work has stopped, before the next work starts.
void ClearStopRequest();

// Registers `action` for the lifetime of this object. Actions run on the watcher thread, newest
// first, with the signal number; they must not wait for the thread that registered them.
class InterruptAction {
 public:
  explicit InterruptAction(std::function<void(int signal)> action);
  ~InterruptAction();
  InterruptAction(const InterruptAction&) = delete;
  InterruptAction& operator=(const InterruptAction&) = delete;

 private:
  int id_;
};

}  // namespace raytime
