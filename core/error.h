// Error types shared by every layer. Input problems are reported with the file (and line, where
// there is one) and what was expected, so a user can fix the input without reading code.
#pragma once

#include <stdexcept>
#include <string>

namespace raytime {

// Bad user input: a file that does not parse, a missing image, an unknown option key.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "path:line: message" (line omitted when 0).
std::string Located(const std::string& path, int line, const std::string& message);

[[noreturn]] void ThrowInput(const std::string& path, int line, const std::string& message);

}  // namespace raytime
