#include "core/atomic_file.h"

#include <signal.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/written_files.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

std::mutex& PendingMutex() {
  static std::mutex mutex;
  return mutex;
}

std::set<std::string>& Pending() {
  static std::set<std::string> pending;
  return pending;
}

// The process id in a temporary's name ".NAME.tmp.PID.N[.old]", or 0 when it is not one.
pid_t TemporaryOwner(const std::string& filename) {
  static const std::regex pattern(R"(^\..+\.tmp\.([0-9]+)\.[0-9]+(\.old)?$)");
  std::smatch match;
  if (!std::regex_match(filename, match, pattern)) return 0;
  try {
    return static_cast<pid_t>(std::stol(match[1].str()));
  } catch (const std::exception&) {
    return 0;
  }
}

bool ProcessRuns(pid_t pid) { return ::kill(pid, 0) == 0 || errno == EPERM; }

// Registers a temporary for the scope of one write.
class PendingTemporary {
 public:
  explicit PendingTemporary(std::string path) : path_(std::move(path)) { RegisterTemporary(path_); }
  ~PendingTemporary() { ForgetTemporary(path_); }
  PendingTemporary(const PendingTemporary&) = delete;
  PendingTemporary& operator=(const PendingTemporary&) = delete;

 private:
  std::string path_;
};

}  // namespace

std::string TemporarySibling(const std::string& path) {
  // The counter keeps two writers of one process (parallel stages, the interrupt watcher) from
  // sharing a name.
  static std::atomic<int> counter{0};
  const fs::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".tmp." + std::to_string(getpid()) +
                             "." + std::to_string(counter++)))
      .string();
}

void RegisterTemporary(const std::string& path) {
  std::lock_guard<std::mutex> lock(PendingMutex());
  Pending().insert(path);
}

void ForgetTemporary(const std::string& path) {
  std::lock_guard<std::mutex> lock(PendingMutex());
  Pending().erase(path);
}

void RemovePendingTemporaryFiles() {
  std::lock_guard<std::mutex> lock(PendingMutex());
  for (const auto& path : Pending()) {
    std::error_code ignored;
    fs::remove_all(path, ignored);
    fs::remove_all(path + ".old", ignored);
  }
  Pending().clear();
}

std::vector<std::string> RemoveStaleTemporaryFiles(const std::string& dir) {
  std::vector<std::string> removed;
  std::error_code error;
  if (!fs::is_directory(dir, error)) return removed;
  std::vector<fs::path> stale;
  for (fs::recursive_directory_iterator it(dir, error), end; !error && it != end;
       it.increment(error)) {
    const pid_t owner = TemporaryOwner(it->path().filename().string());
    if (owner == 0) continue;
    if (it->is_directory()) it.disable_recursion_pending();
    if (owner != getpid() && !ProcessRuns(owner)) stale.push_back(it->path());
  }
  for (const auto& path : stale) {
    std::error_code ignored;
    if (fs::remove_all(path, ignored) > 0) removed.push_back(path.string());
  }
  std::sort(removed.begin(), removed.end());
  return removed;
}

void WriteAtomically(const std::string& path,
                     const std::function<void(const std::string&)>& write) {
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent);
  // A rename cannot put a file over a folder; said before anything is written, not as "Is a
  // directory" about a temporary name. The folder is not raytime's: it writes a file here.
  std::error_code error;
  if (fs::is_directory(fs::symlink_status(path, error))) {
    throw InputError(path +
                     ": a folder is where raytime writes this file (raytime did not make it); "
                     "move it away, or give another work directory");
  }
  const std::string tmp = TemporarySibling(path);
  const PendingTemporary pending(tmp);
  try {
    write(tmp);
    fs::rename(tmp, path);
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

namespace {

// Replaces folder `path` by the complete `tmp`, carrying `theirs` (FilesNotWritten(path)) over.
// Under the temporaries' lock, so that an interruption's clean-up, which removes this process's
// temporaries, never runs while the user's files are in one. A carry that fails midway keeps the
// earlier folder, with what it still holds of theirs, under a name no clean-up removes.
void ReplaceFolder(const fs::path& path, const fs::path& tmp,
                   const std::vector<std::string>& theirs, const std::string& keep_old_as) {
  std::lock_guard<std::mutex> lock(PendingMutex());
  std::error_code ignored;
  if (!fs::exists(fs::symlink_status(path, ignored))) {
    fs::rename(tmp, path);
    return;
  }
  const fs::path old = tmp.string() + ".old";
  fs::remove_all(old, ignored);
  fs::rename(path, old);
  try {
    fs::rename(tmp, path);
  } catch (...) {
    fs::rename(old, path, ignored);
    throw;
  }
  try {
    CarryEntriesOver(theirs, old.string(), path.string());
  } catch (const std::exception& e) {
    const fs::path kept = UnusedPath(path.string() + ".kept." + std::to_string(getpid()));
    fs::rename(old, kept, ignored);
    throw std::runtime_error(std::string(e.what()) + "; the earlier " + path.string() +
                             ", with the files raytime did not write, is kept as " + kept.string());
  }
  if (keep_old_as.empty()) {
    fs::remove_all(old, ignored);
    return;
  }
  fs::rename(old, UnusedPath(keep_old_as));
}

}  // namespace

void WriteDirectoryAtomically(const std::string& path,
                              const std::function<void(const std::string&)>& write) {
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent);
  std::error_code ignored;
  if (fs::exists(fs::symlink_status(path, ignored)) && !fs::is_directory(path, ignored)) {
    throw InputError(path +
                     " is a file, and raytime writes a folder there: move it away and run "
                     "again (it was not replaced)");
  }
  const std::string tmp = TemporarySibling(path);
  const PendingTemporary pending(tmp);
  fs::remove_all(tmp, ignored);
  try {
    fs::create_directories(tmp);
    write(tmp);
    const std::vector<std::string> theirs = FilesNotWritten(path);
    const std::vector<std::string> colliding = CollidingEntries(theirs, path, tmp);
    const fs::path record = fs::path(path) / kWrittenFilesRecord;
    const bool recorded = fs::exists(record, ignored);
    if (!colliding.empty() && recorded) {
      throw InputError((fs::path(path) / colliding.front()).string() +
                       " was not written by raytime (or has changed since it was: " +
                       record.string() + " lists what it wrote), and raytime writes " +
                       colliding.front() + " there: move it out of " + path +
                       " and run again (nothing in " + path + " was replaced)");
    }
    // A folder without a record was written by an earlier raytime, which kept none (or by
    // someone else): what collides stays in it, kept whole as PATH.before-record; the rest is
    // carried over.
    std::vector<std::string> carried;
    for (const std::string& entry : theirs) {
      const bool collides = std::any_of(colliding.begin(), colliding.end(), [&](const auto& c) {
        return c == entry || c.rfind(entry + "/", 0) == 0;
      });
      if (!collides) carried.push_back(entry);
    }
    RecordWrittenFiles(tmp);
    ReplaceFolder(path, tmp, carried, colliding.empty() ? "" : path + ".before-record");
  } catch (...) {
    fs::remove_all(tmp, ignored);
    throw;
  }
}

void WriteTextFileAtomically(const std::string& path, const std::string& contents) {
  WriteAtomically(path, [&](const std::string& tmp) {
    errno = 0;
    std::ofstream out(tmp, std::ios::binary);
    out << contents;
    out.close();
    if (!out) {
      const int error = errno;
      throw std::runtime_error("cannot write " + path + WriteFailureReason(path, error));
    }
  });
}

std::string WriteFailureReason(const std::string& path, int error) {
  // Below this much free space a failed write is taken for a full disk whatever errno says
  // (HDF5 and iostreams do not always leave it set).
  constexpr unsigned long long kNearlyFullBytes = 1 << 20;
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  struct statvfs stats;
  const bool known = ::statvfs(dir.c_str(), &stats) == 0;
  const unsigned long long free_bytes =
      known ? static_cast<unsigned long long>(stats.f_bavail) * stats.f_frsize : 0;
  if (error == ENOSPC || error == EDQUOT || (known && free_bytes < kNearlyFullBytes)) {
    return ": no space left on device (" + std::to_string(free_bytes) + " bytes free in " +
           dir.string() + "); free some space and run again";
  }
  if (error == EMFILE || error == ENFILE) return std::string(": ") + std::strerror(error);
  // Only the errors of a write itself: errno may be left over from an unrelated call.
  if (error == EFBIG || error == EIO || error == EROFS)
    return std::string(": ") + std::strerror(error);
  return "";
}

bool PathExists(const std::string& path) {
  std::error_code error;
  return std::filesystem::exists(path, error);
}

std::string ReadTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in)
    ThrowInput(path, 0, std::string("cannot open file for reading (") + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace raytime
