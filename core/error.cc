#include "core/error.h"

namespace raytime {

std::string Located(const std::string& path, int line, const std::string& message) {
  if (line > 0) return path + ":" + std::to_string(line) + ": " + message;
  return path + ": " + message;
}

void ThrowInput(const std::string& path, int line, const std::string& message) {
  throw InputError(Located(path, line, message));
}

}  // namespace raytime
