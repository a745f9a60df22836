// Atomic file output: write to a temporary sibling, then rename over the target, so a failure
// never leaves a half-written file under the final name.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace raytime {

// Calls `write(temporary_path)`, then renames the temporary file onto `path`. If `write` throws,
// the temporary file is removed and the exception propagates; `path` is untouched.
void WriteAtomically(const std::string& path, const std::function<void(const std::string&)>& write);

// Same for a whole directory (e.g. a COLMAP model): `write` fills a temporary sibling directory,
// which then replaces `path` (an existing directory at `path` is removed only after success).
// Only what raytime wrote is replaced (core/written_files.h): the other files of an existing
// `path` are carried into the new one, and one under a name `write` wrote throws InputError naming
// it, `path` untouched. A `path` without a record (an earlier raytime's, which kept none) is kept
// whole as `path`.before-record when something in it collides.
void WriteDirectoryAtomically(const std::string& path,
                              const std::function<void(const std::string&)>& write);

void WriteTextFileAtomically(const std::string& path, const std::string& contents);

// Why writing `path` failed, for the end of an error message: ": no space left on device (N bytes
// free in DIR)" when its file system is full, else the system's reason for `error` (an errno value
// read right after the failure) when it is a write's own (EFBIG, EIO, EROFS), "" otherwise.
std::string WriteFailureReason(const std::string& path, int error);

// Whole file as a string; throws InputError naming the path when it cannot be read.
std::string ReadTextFile(const std::string& path);

// Whether `path` exists, false when the system cannot even look it up (a name too long, say):
// for paths built from names read out of a file, which must not escape as filesystem_error.
bool PathExists(const std::string& path);

// Temporary files. Every writer names its temporary sibling ".NAME.tmp.PID.N" (N counts within
// the process) and registers it while it exists, so that an interrupted run removes its own
// (RemovePendingTemporaryFiles, called by core/interrupt.h) and the next run in a work directory
// removes those a killed run left (RemoveStaleTemporaryFiles).
std::string TemporarySibling(const std::string& path);
// Registers / forgets a temporary path of this process (file or folder).
void RegisterTemporary(const std::string& path);
void ForgetTemporary(const std::string& path);
// Removes every registered temporary of this process.
void RemovePendingTemporaryFiles();
// Removes, below `dir`, temporaries whose process no longer runs; returns the paths removed.
std::vector<std::string> RemoveStaleTemporaryFiles(const std::string& dir);

}  // namespace raytime
