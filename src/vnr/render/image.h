#pragma once
// The renderer's images: the public Image, its files and metrics (vnr/image.h).
#include "vnr/image.h"
