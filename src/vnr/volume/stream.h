#pragma once
// Streaming volumes that need not fit in memory (scan_value_range, for_each_slab): declared in the
// public vnr/volume.h, implemented in volume/stream.cpp.
#include "vnr/volume.h"
