#pragma once
// The recording used when no input is given: the synthetic textured room (300 frames, exact ground
// truth), rendered once into rawlogs/generated/synthetic_room.rawlog so that it needs no download and
// can be opened in RawLogViewer.
#include <string>

#include "vofusion/sim/synthetic_sequence.h"

namespace vofusion {

// Path of the default rawlog, rendering it first (with a progress line) if it does not exist yet or is
// not this simulator's render (recordingRenderedBy); empty when a stop was asked for (stopRequested())
// while rendering: nothing is left of it.
std::string defaultRecording();
// The rawlog at `path` as `seq` renders it: rendered (again) unless the fingerprint beside it
// (<path>.made-by) is seq's (its first and last frames: images, stamps, poses) and the rawlog's (size,
// time: not rendered over by hand since). A recording kept after the
// simulator changed (its scene, noise or path) was every later default run's input, without a word.
// Empty when a stop was asked for while rendering.
std::string recordingRenderedBy(const sim::SyntheticSequence& seq, const std::string& path);
// The synthetic recording `seq` rendered into the rawlog at `path` (images and ground truth beside it;
// an existing rawlog replaced only with `replace`), with a progress line; false, and nothing left, when
// a stop was asked for (stopRequested()) before its end.
bool renderRecording(const sim::SyntheticSequence& seq, const std::string& path, bool replace = false);

}  // namespace vofusion
