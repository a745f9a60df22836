#include "core/interrupt.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <map>
#include <mutex>
#include <thread>

#include "core/atomic_file.h"

namespace raytime {
namespace {

int g_pipe[2] = {-1, -1};
std::atomic<bool> g_interrupting{false};
std::atomic<bool> g_stop_requested{false};

std::mutex& ActionsMutex() {
  static std::mutex mutex;
  return mutex;
}

std::map<int, std::function<void(int)>>& Actions() {
  static std::map<int, std::function<void(int)>> actions;
  return actions;
}

void OnSignal(int signal) {
  const unsigned char byte = static_cast<unsigned char>(signal);
  const int saved = errno;
  [[maybe_unused]] const ssize_t written = ::write(g_pipe[1], &byte, 1);
  errno = saved;
}

void RunActions(int signal) {
  {
    std::lock_guard<std::mutex> lock(ActionsMutex());
    for (auto it = Actions().rbegin(); it != Actions().rend(); ++it) {
      try {
        it->second(signal);
      } catch (...) {
        // An action that fails must not keep the others from running.
      }
    }
  }
  RemovePendingTemporaryFiles();
}

void Watch() {
  unsigned char byte = 0;
  while (::read(g_pipe[0], &byte, 1) != 1) {
    if (errno != EINTR) return;
  }
  const int signal = byte;
  g_interrupting = true;
  RunActions(signal);
  ::_exit(128 + signal);
}

}  // namespace

bool Interrupting() { return g_interrupting; }

void AwaitInterruptExit() {
  if (g_stop_requested) throw StopRequested{};
  for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
}

void RequestStop(int signal) {
  // Set first: work that passes a StopPoint after the actions wrote "interrupted" would otherwise
  // go on and record an end of its own.
  g_stop_requested = true;
  g_interrupting = true;
  RunActions(signal);
}

void StopPoint() {
  if (g_stop_requested) throw StopRequested{};
}

bool StopWasRequested() { return g_stop_requested; }

void ClearStopRequest() {
  g_stop_requested = false;
  g_interrupting = false;
}

void InstallInterruptHandler() {
  if (g_pipe[0] >= 0) return;
  if (::pipe2(g_pipe, O_CLOEXEC) != 0) return;
  struct sigaction action = {};
  action.sa_handler = OnSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  ::sigaction(SIGINT, &action, nullptr);
  ::sigaction(SIGTERM, &action, nullptr);
  ::sigaction(SIGHUP, &action, nullptr);
  std::thread(Watch).detach();
}

InterruptAction::InterruptAction(std::function<void(int)> action) {
  static int next_id = 0;
  std::lock_guard<std::mutex> lock(ActionsMutex());
  id_ = next_id++;
  Actions()[id_] = std::move(action);
}

InterruptAction::~InterruptAction() {
  std::lock_guard<std::mutex> lock(ActionsMutex());
  Actions().erase(id_);
}

}  // namespace raytime
