// libFuzzer harness: the MRPT rawlog reader (RawlogSource) on arbitrary file contents, read to the end.
// Bad input may only throw vofusion::InputError; set FUZZ_RAWLOG_LENIENT=1 to also accept any
// std::exception (what the apps would still turn into a one-line error).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "vofusion/core/errors.h"
#include "vofusion/io/rawlog.h"

namespace {
const std::string& tempPath() {
  static const std::string p = "/tmp/vofusion-fuzz-" + std::to_string(::getpid()) + ".rawlog";
  return p;
}
const bool kLenient = std::getenv("FUZZ_RAWLOG_LENIENT") != nullptr;
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::FILE* f = std::fopen(tempPath().c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    vofusion::RawlogSource src(tempPath(), {});
    vofusion::Frame frame;
    std::size_t n = 0;
    while (src.next(frame)) {
      if (!frame.valid() || frame.depth.type() != CV_32FC1 || frame.rgb.type() != CV_8UC3) __builtin_trap();
      if (frame.rgb.size() != frame.depth.size()) __builtin_trap();
      if (++n > src.size()) __builtin_trap();
    }
  } catch (const vofusion::InputError&) {
  } catch (const std::exception&) {
    if (!kLenient) throw;
  }
  return 0;
}
