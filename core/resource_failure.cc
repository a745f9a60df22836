#include "core/resource_failure.h"

#include <sys/resource.h>

#include <cerrno>
#include <cstdio>
#include <new>
#include <system_error>

#include "core/error.h"

namespace raytime {
namespace {

bool Contains(const std::string& text, const char* part) {
  return text.find(part) != std::string::npos;
}

// "1.2 GB" for a limit in bytes, "unlimited" for none.
std::string LimitText(int resource, bool bytes) {
  struct rlimit limit {};
  if (::getrlimit(resource, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return "unlimited";
  if (!bytes) return std::to_string(limit.rlim_cur);
  char text[32];
  std::snprintf(text, sizeof(text), "%.2f GB", static_cast<double>(limit.rlim_cur) / 1e9);
  return text;
}

}  // namespace

std::string ResourceNamedIn(const std::string& text) {
  if (Contains(text, "Too many open files") || Contains(text, "too many open files")) {
    return "open_files";
  }
  if (Contains(text, "No space left on device") || Contains(text, "no space left on device")) {
    return "disk_space";
  }
  if (Contains(text, "Insufficient memory") || Contains(text, "bad_alloc") ||
      Contains(text, "Cannot allocate memory") || Contains(text, "out of memory") ||
      Contains(text, "failed to map segment")) {
    return "memory";
  }
  if (Contains(text, "pthread_create") || Contains(text, "Thread creation failed") ||
      Contains(text, "Resource temporarily unavailable")) {
    return "threads";
  }
  return "";
}

std::string ResourceAdvice(const std::string& cause) {
  if (cause == "memory") {
    return "out of memory (address-space limit, ulimit -v: " + LimitText(RLIMIT_AS, true) +
           "): free memory or raise the limit, or ask for less (smaller images, fewer "
           "features.max_features, refine.max_matches_per_pair, refine.num_threads)";
  }
  if (cause == "threads") {
    return "cannot start a thread (processes/threads limit, ulimit -u: " +
           LimitText(RLIMIT_NPROC, false) +
           "; address-space limit, ulimit -v: " + LimitText(RLIMIT_AS, true) +
           "; each thread needs a stack): raise the limits, or set refine.num_threads lower";
  }
  if (cause == "open_files") {
    return "too many open files (limit, ulimit -n: " + LimitText(RLIMIT_NOFILE, false) +
           "): raise it (ulimit -n 4096) and run again";
  }
  if (cause == "disk_space") return "no space left on device: free some space and run again";
  return "";
}

FailureDescription DescribeFailure(const std::exception& error) {
  FailureDescription description;
  description.message = error.what();
  // OpenCV's messages end with a newline.
  description.message.erase(description.message.find_last_not_of(" \n") + 1);
  // A file that cannot be opened is reported as an input error by its reader, whatever the
  // reason: out of file descriptors is no fault of the input.
  if (dynamic_cast<const InputError*>(&error) != nullptr &&
      ResourceNamedIn(description.message) != "open_files") {
    description.cause = "input";
    description.exit_code = kExitInput;
    return description;
  }
  std::string cause;
  if (dynamic_cast<const std::bad_alloc*>(&error) != nullptr) {
    cause = "memory";
  } else if (const auto* system = dynamic_cast<const std::system_error*>(&error)) {
    // std::thread reports a thread it cannot start as EAGAIN.
    if (system->code() == std::errc::resource_unavailable_try_again) cause = "threads";
    if (system->code() == std::errc::too_many_files_open ||
        system->code() == std::errc::too_many_files_open_in_system) {
      cause = "open_files";
    }
    if (system->code() == std::errc::not_enough_memory) cause = "memory";
    if (system->code() == std::errc::no_space_on_device) cause = "disk_space";
  }
  if (cause.empty()) cause = ResourceNamedIn(description.message);
  if (cause.empty()) {
    description.cause = "error";
    return description;
  }
  description.cause = cause;
  description.exit_code = kExitResource;
  // A full disk's message already says what to do (core/atomic_file.h).
  if (cause != "disk_space") description.message += ": " + ResourceAdvice(cause);
  return description;
}

void RaiseOpenFileLimit() {
  struct rlimit limit {};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur >= limit.rlim_max) return;
  limit.rlim_cur = limit.rlim_max;
  ::setrlimit(RLIMIT_NOFILE, &limit);
}

}  // namespace raytime
