#include "core/user_paths.h"

#include <pwd.h>
#include <unistd.h>

#include <cstdlib>
#include <vector>

#include "core/error.h"

namespace raytime {
namespace {

// The home folder of `user` ("" = this process's user) from the password database; "" if none.
std::string HomeOf(const std::string& user) {
  std::vector<char> buffer(16384);
  struct passwd entry {};
  struct passwd* found = nullptr;
  if (user.empty()) {
    ::getpwuid_r(::getuid(), &entry, buffer.data(), buffer.size(), &found);
  } else {
    ::getpwnam_r(user.c_str(), &entry, buffer.data(), buffer.size(), &found);
  }
  return found != nullptr && found->pw_dir != nullptr ? found->pw_dir : "";
}

}  // namespace

std::string ExpandUser(const std::string& path) {
  if (path.empty() || path[0] != '~') return path;
  const size_t slash = path.find('/');
  const std::string user =
      path.substr(1, slash == std::string::npos ? std::string::npos : slash - 1);
  std::string home;
  if (user.empty()) {
    const char* variable = std::getenv("HOME");
    home = variable != nullptr && variable[0] != '\0' ? variable : HomeOf("");
  } else {
    home = HomeOf(user);
    // A shell leaves "~NAME" of no known user as it is; a folder named so in the working
    // directory is never what was meant.
    if (home.empty()) {
      throw InputError(path + ": no user '" + user +
                       "' (a leading ~NAME is the home folder of user NAME)");
    }
  }
  if (home.empty()) return path;
  return slash == std::string::npos ? home : home + path.substr(slash);
}

}  // namespace raytime
