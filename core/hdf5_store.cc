#include "core/hdf5_store.h"
