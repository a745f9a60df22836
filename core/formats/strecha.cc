#include "core/formats/strecha.h"
