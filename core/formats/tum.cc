#include "core/formats/tum.h"
