#pragma once
// What the CPU running the program can do, for the loops that have an AVX2 or AVX-512 build beside
// their scalar one (chosen at run time: the program itself is built for plain x86-64).

namespace vofusion {

// Each asked once, when first needed (also right for an object made during another file's static
// start-up).
inline bool cpuHasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}
inline bool cpuHasAvx512Popcount() {
  static const bool has = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                          __builtin_cpu_supports("avx512vpopcntdq");
  return has;
}

}  // namespace vofusion
