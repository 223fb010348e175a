#include "vofusion/io/frame_source.h"

namespace vofusion {

bool IndexedFrameSource::next(Frame& frame) {
  if (pos_ >= size()) return false;
  frame = read(pos_++);
  return true;
}

}  // namespace vofusion
