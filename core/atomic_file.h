// Atomic file output: write to a temporary sibling, then rename over the target, so a failure
// never leaves a half-written file under the final name.
#pragma once

#include <functional>
#include <string>

namespace raytime {

// Calls `write(temporary_path)`, then renames the temporary file onto `path`. If `write` throws,
// the temporary file is removed and the exception propagates; `path` is untouched.
void WriteAtomically(const std::string& path, const std::function<void(const std::string&)>& write);

// Same for a whole directory (e.g. a COLMAP model): `write` fills a temporary sibling directory,
// which then replaces `path` (an existing directory at `path` is removed only after success).
void WriteDirectoryAtomically(const std::string& path,
                              const std::function<void(const std::string&)>& write);

void WriteTextFileAtomically(const std::string& path, const std::string& contents);

// Whole file as a string; throws InputError naming the path when it cannot be read.
std::string ReadTextFile(const std::string& path);

}  // namespace raytime
