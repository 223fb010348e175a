// libFuzzer harness: TUM rgb.txt/depth.txt parsing. Bad input may only throw vofusion::InputError.
#include <cstddef>
#include <cstdint>
#include <string>

#include "vofusion/core/errors.h"
#include "vofusion/io/tum_source.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const auto list = vofusion::parseTumList(text, "fuzz.txt");
    // Whatever parses must be usable: strictly increasing stamps, non-empty names.
    for (std::size_t i = 0; i < list.size(); ++i) {
      if (list[i].file.empty()) __builtin_trap();
      if (i > 0 && !(list[i].timestamp > list[i - 1].timestamp)) __builtin_trap();
    }
    vofusion::associate(list, list, 0.02);
  } catch (const vofusion::InputError&) {
  }
  return 0;
}
