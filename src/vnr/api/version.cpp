#include "vnr/version.h"

namespace vnr {
const char* version() { return VNR_VERSION; }
}  // namespace vnr
