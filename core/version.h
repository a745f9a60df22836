#pragma once

namespace raytime {
// The project version, written into every output's provenance.
const char* Version();
}  // namespace raytime
