#include "evaluate/pose_errors.h"
