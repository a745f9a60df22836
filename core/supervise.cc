#include "core/supervise.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace raytime {
namespace {

volatile sig_atomic_t g_child = 0;

void Forward(int signal) {
  if (g_child > 0) ::kill(static_cast<pid_t>(g_child), signal);
}

// The last `max_bytes` of what passed, from a line start where one falls inside.
void KeepTail(std::string* tail, const char* data, size_t size, size_t max_bytes) {
  tail->append(data, size);
  if (tail->size() <= max_bytes) return;
  tail->erase(0, tail->size() - max_bytes);
  const size_t line = tail->find('\n');
  if (line != std::string::npos && line + 1 < tail->size()) tail->erase(0, line + 1);
}

// Copies the child's stderr to ours until the pipe ends, or until the child has ended and the
// pipe is drained (a grandchild, COLMAP or a trainer, may hold it open longer); returns the tail,
// `status` how the child ended.
std::string PassStderrThrough(int fd, pid_t child, ProcessStatus* status) {
  std::string tail;
  bool ended = false;
  char buffer[4096];
  for (;;) {
    struct pollfd poll_fd = {fd, POLLIN, 0};
    const int ready = ::poll(&poll_fd, 1, ended ? 0 : 200);
    if (ready < 0 && errno == EINTR) continue;
    if (ready < 0) break;
    if (ready > 0) {
      const ssize_t n = ::read(fd, buffer, sizeof(buffer));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      [[maybe_unused]] const ssize_t written = ::write(STDERR_FILENO, buffer, n);
      KeepTail(&tail, buffer, static_cast<size_t>(n), 2048);
      continue;
    }
    if (ended) break;
    ended = WaitProcessFor(child, 0, status);
  }
  if (!ended) *status = WaitProcess(child);
  return tail;
}

}  // namespace

std::string DescribeSignal(int signal) {
  const char* name = ::strsignal(signal);
  return "signal " + std::to_string(signal) + (name ? std::string(" (") + name + ")" : "");
}

std::optional<SupervisedEnd> ForkSupervised() {
  const char* off = std::getenv("RAYTIME_UNSUPERVISED");
  if (off != nullptr && std::string(off) == "1") return std::nullopt;
  const bool capture = ::isatty(STDERR_FILENO) != 1;
  int pipe_fds[2] = {-1, -1};
  if (capture && ::pipe2(pipe_fds, O_CLOEXEC) != 0) return std::nullopt;
  const pid_t parent = ::getpid();
  const pid_t child = ::fork();
  if (child < 0) {
    if (capture) {
      ::close(pipe_fds[0]);
      ::close(pipe_fds[1]);
    }
    return std::nullopt;
  }
  if (child == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::raise(SIGTERM);
    if (capture) {
      ::dup2(pipe_fds[1], STDERR_FILENO);
      ::close(pipe_fds[0]);
      ::close(pipe_fds[1]);
    }
    return std::nullopt;
  }
  g_child = child;
  struct sigaction action = {};
  action.sa_handler = Forward;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  for (const int signal : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) ::sigaction(signal, &action, nullptr);
  SupervisedEnd end;
  end.child = child;
  if (capture) {
    ::close(pipe_fds[1]);
    end.stderr_tail = PassStderrThrough(pipe_fds[0], child, &end.status);
    ::close(pipe_fds[0]);
  } else {
    end.status = WaitProcess(child);
  }
  return end;
}

}  // namespace raytime
