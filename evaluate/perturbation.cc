#include "evaluate/perturbation.h"
