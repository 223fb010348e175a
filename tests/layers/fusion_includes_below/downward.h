#pragma once
// A fixture for Layers.*: a fusion header using only layers below it, which the layer check accepts.
#include "vofusion/core/frame.h"
#include "vofusion/fusion/kinfu.h"
#include "vofusion/registration/projective_icp.h"
#include "vofusion/tracking/tracker.h"
