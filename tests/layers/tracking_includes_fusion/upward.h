#pragma once
// A fixture for Layers.*: a tracking header reaching up to the map it tracks against (fusion sits above
// tracking: a frame flows io -> odometry -> tracking -> fusion), which the layer check refuses.
#include "vofusion/fusion/kinfu.h"
#include "vofusion/tracking/tracker_params.h"
