#pragma once
// floor(x) as an int: the integer std::floor gives for -2^31 <= x < 2^31 (outside that range, and for
// NaN, the conversion overflows as the cast of std::floor's result did). The build targets plain
// x86-64 (SSE2, no roundss), where std::floor is a 15-instruction sequence; this is a few, without a
// branch. Test: FloorToInt.IsStdFloor.

namespace vofusion {

inline int floorToInt(float x) {
  const int i = static_cast<int>(x);  // towards zero
  return i - (x < static_cast<float>(i));
}

}  // namespace vofusion
