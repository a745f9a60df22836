#include "core/version.h"

namespace raytime {
const char* Version() { return RAYTIME_VERSION; }
}  // namespace raytime
