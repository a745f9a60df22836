#include "bootstrap/view_graph.h"

namespace raytime {}  // namespace raytime
