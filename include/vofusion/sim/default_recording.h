#pragma once
// The recording used when no input is given: the synthetic textured room (300 frames, exact ground
// truth), rendered once into rawlogs/generated/synthetic_room.rawlog so that it needs no download and
// can be opened in RawLogViewer.
#include <string>

namespace vofusion {

// Path of the default rawlog, rendering it first (with a progress line) if it does not exist yet.
std::string defaultRecording();

}  // namespace vofusion
