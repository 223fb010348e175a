#pragma once
// floor(x) as an int for |x| < 2^31: the integer std::floor gives. The build targets plain x86-64 (SSE2,
// no roundss), where std::floor is a 15-instruction sequence; this is four. Test: FloorToInt.IsStdFloor.

namespace vofusion {

inline int floorToInt(float x) {
  const int i = static_cast<int>(x);  // towards zero
  return i - (x < static_cast<float>(i));
}

}  // namespace vofusion
