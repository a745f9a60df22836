#include "core/formats/nerfstudio.h"
