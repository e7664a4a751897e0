#pragma once
// vnr's public C++ API: the objects every front end (the `vnr` CLI, the viewer, the Python module)
// drives. Include this one header; see examples/ and docs/ARCHITECTURE.md ("Public API").
#include "vnr/model.h"
#include "vnr/renderer.h"
#include "vnr/version.h"
#include "vnr/volume.h"
