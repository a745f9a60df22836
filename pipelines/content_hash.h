// Content hashes (XXH3, 128 bit) that decide whether a stage can be skipped.
#pragma once

#include <string>

namespace raytime {

std::string HashBytes(const std::string& bytes);        // 32 hex digits
std::string HashFileContents(const std::string& path);  // InputError naming an unreadable file

}  // namespace raytime
