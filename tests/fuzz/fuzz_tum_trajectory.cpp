// libFuzzer harness: TUM trajectory parsing (groundtruth.txt, estimates) and interpolation.
// Bad input may only throw vofusion::InputError.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "vofusion/core/errors.h"
#include "vofusion/core/trajectory.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const vofusion::Trajectory t = vofusion::parseTumTrajectory(text, "fuzz.txt");
    for (std::size_t i = 0; i < t.size(); ++i) {
      if (!std::isfinite(t[i].timestamp) || !std::isfinite(t[i].pose.x())) __builtin_trap();
      if (i > 0 && !(t[i].timestamp > t[i - 1].timestamp)) __builtin_trap();
    }
    if (!t.empty()) {
      mrpt::poses::CPose3D p;
      vofusion::interpolatePose(t, 0.5 * (t.front().timestamp + t.back().timestamp), 1e9, p);
    }
  } catch (const vofusion::InputError&) {
  }
  return 0;
}
