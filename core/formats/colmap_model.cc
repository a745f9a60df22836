#include "core/formats/colmap_model.h"
