#pragma once
// vnr's online training and rendering API: OnlineLoop interleaves a Trainer backend's steps with frames
// of the current model (macro-cells from the training samples); TrainPreview writes such frames to PNG
// files every N steps (the side work of a TrainingSession in `vnr train --preview-every`).
#include "vnr/online/online_loop.h"
#include "vnr/online/preview.h"
#include "vnr/trainer.h"
