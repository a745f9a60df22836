// Paths as a shell would read them. A path typed into a YAML file, a quoted --workdir '~/wk' or a
// --set dataset.root=~/ds reaches raytime with its tilde unexpanded: taken literally it names a
// folder "~" in the working directory.
#pragma once

#include <string>

namespace raytime {

// `path` with a leading "~" or "~/..." replaced by $HOME (the password database's home when HOME
// is unset or empty) and "~NAME" or "~NAME/..." by NAME's home, as POSIX shells expand a word's
// leading tilde; anything else unchanged. InputError for a "~NAME" of no known user (a shell would
// leave it as it is, naming a folder "~NAME" that is never what was meant).
std::string ExpandUser(const std::string& path);

}  // namespace raytime
