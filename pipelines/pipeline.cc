#include "pipelines/pipeline.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "pipelines/sweep.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// One run at a time in a work directory: two runs into one interleave their stages' outputs
// (the summary of one beside the refined poses of the other). An exclusive flock on
// WORKDIR/.raytime/run.lock, released by the kernel however the holder ends (kill -9 included);
// the file holds the holder's pid, for the refusal's message. A file system that cannot lock
// (some network mounts) runs unlocked rather than not at all.
class WorkdirLock {
 public:
  explicit WorkdirLock(const std::string& workdir) {
    const fs::path dir = fs::path(workdir) / ".raytime";
    std::error_code error;
    fs::create_directories(dir, error);
    if (error) {
      throw InputError(workdir + ": cannot create the work directory (" + error.message() + ")");
    }
    const std::string path = (dir / "run.lock").string();
    fd_ = ::open(path.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644);
    if (fd_ < 0) {
      throw InputError(workdir + ": cannot write in the work directory (" + std::strerror(errno) +
                       ")");
    }
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      const int reason = errno;
      if (reason == EWOULDBLOCK) {
        char buffer[32] = {0};
        const ssize_t n = ::pread(fd_, buffer, sizeof(buffer) - 1, 0);
        const std::string pid = n > 0 ? std::string(buffer, static_cast<size_t>(n)) : "?";
        ::close(fd_);
        fd_ = -1;
        throw InputError(workdir + ": another raytime run (pid " + pid +
                         ") is using this work directory; wait for it to end, or give this run "
                         "another --workdir");
      }
      return;  // no locks on this file system
    }
    const std::string pid = std::to_string(::getpid());
    if (::ftruncate(fd_, 0) == 0) {
      [[maybe_unused]] const ssize_t written = ::pwrite(fd_, pid.data(), pid.size(), 0);
    }
  }
  ~WorkdirLock() {
    if (fd_ >= 0) ::close(fd_);
  }
  WorkdirLock(const WorkdirLock&) = delete;
  WorkdirLock& operator=(const WorkdirLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace

nlohmann::json RunPipeline(const PipelineSpec& spec, const RunOptions& options) {
  const std::string workdir = !options.workdir.empty() ? options.workdir : spec.workdir;
  if (workdir.empty()) {
    throw InputError(spec.path + ": no work directory (set 'workdir' or pass --workdir)");
  }
  if (!spec.sweep.empty()) {
    const WorkdirLock lock(workdir);
    return RunSweep(spec, workdir, options);
  }
  ValidatePipeline(spec);
  const WorkdirLock lock(workdir);
  return RunStages(spec, workdir, options);
}

}  // namespace raytime
