#include "core/shipped_files.h"

#include <cstdlib>
#include <system_error>

namespace raytime {
namespace {

// The executable's own folder; empty when /proc is not mounted (a bare chroot).
std::filesystem::path ExecutableDirectory() {
  std::error_code error;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", error);
  return error ? std::filesystem::path() : exe.parent_path();
}

}  // namespace

std::string ShippedDirectory::Searched() const {
  std::string text;
  for (const auto& candidate : searched) {
    if (!text.empty()) text += ", ";
    text += candidate.string();
  }
  return text + (from_env ? " (from " : " (or set ") + env_variable + ")";
}

ShippedDirectory FindShippedDirectory(const char* env_variable, const std::string& relative) {
  ShippedDirectory found;
  found.env_variable = env_variable;
  const char* env = std::getenv(env_variable);
  found.from_env = env != nullptr && *env != '\0';
  if (found.from_env) {
    found.searched = {env};
  } else {
    // RAYTIME_INSTALLED_DATA_DIR: share/raytime relative to the installed bin/ (GNUInstallDirs,
    // core/CMakeLists.txt), so a relocated prefix (cmake --install --prefix, the .deb's /usr)
    // still finds its own files.
    const std::filesystem::path bin = ExecutableDirectory();
    if (!bin.empty()) {
      found.searched.push_back((bin / RAYTIME_INSTALLED_DATA_DIR / relative).lexically_normal());
    }
    found.searched.push_back(std::filesystem::path(RAYTIME_SOURCE_DIR) / relative);
  }
  for (const auto& candidate : found.searched) {
    std::error_code error;
    if (std::filesystem::is_directory(candidate, error)) {
      found.path = candidate;
      break;
    }
  }
  return found;
}

}  // namespace raytime
