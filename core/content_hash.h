// Content hashes (XXH3, 128 bit): whether a stage can be skipped (pipelines/), whether a file is
// the one raytime wrote (core/written_files.h).
#pragma once

#include <string>

namespace raytime {

std::string HashBytes(const std::string& bytes);        // 32 hex digits
std::string HashFileContents(const std::string& path);  // InputError naming an unreadable file
// HashFileContents of this executable, computed once per process (read through /proc/self/exe,
// which opens the running binary even where a rebuild has unlinked its path). Part of every
// content key, so a rebuilt raytime never reuses what different code computed.
const std::string& ExecutableHash();

}  // namespace raytime
