#pragma once
// Model, files, evaluation, decoding and config sizing: one include for the four headers they live in.
#include "vnr/train/config_sizing.h"
#include "vnr/train/decoder.h"
#include "vnr/train/evaluate.h"
#include "vnr/train/model.h"
