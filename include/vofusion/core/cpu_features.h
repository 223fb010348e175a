#pragma once
// What the CPU running the program can do, for the loops that have an AVX2 build beside their scalar
// one (chosen at run time: the program itself is built for plain x86-64).

namespace vofusion {

inline bool cpuHasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

}  // namespace vofusion
