#pragma once
// A fixture for Layers.*: a fusion header reaching up to the pipeline, which the layer check refuses.
#include "vofusion/core/frame.h"
#include "vofusion/pipeline/reconstruction.h"
