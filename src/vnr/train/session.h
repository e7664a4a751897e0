#pragma once
// TrainingSession (vnr/trainer.h) with the train layer's types it names complete: the backends, the
// training data, compact storage.
#include "vnr/trainer.h"
#include "vnr/train/model_io.h"
#include "vnr/train/rate_control.h"
#include "vnr/train/trainer.h"
#include "vnr/train/trainer_backend.h"
#include "vnr/train/training_data.h"
