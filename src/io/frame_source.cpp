#include "vofusion/io/frame_source.h"

namespace vofusion {

bool IndexedFrameSource::next(Frame& frame) {
  if (pos_ >= size()) return false;
  try {
    frame = read(pos_++);
  } catch (const InputError& e) {
    // The folder and its lists were checked when the source opened: what fails now is this frame's.
    throw DamagedFrame(e);
  }
  return true;
}

}  // namespace vofusion
