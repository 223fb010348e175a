#!/usr/bin/env bash
# Builds the libFuzzer harnesses with clang (independent of the g++/CMake build) and runs each for a
# given time. See tests/fuzz/README.md.
#   tests/fuzz/run.sh [seconds_per_harness=60] [harness...]    harnesses: tum_list tum_trajectory rawlog
# Env: FUZZ_BUILD (default build-fuzz), CXX (default clang++), JOBS (libFuzzer -jobs, default 1),
#      NICE (default 19), RSS_LIMIT_MB (libFuzzer -rss_limit_mb, also the malloc limit; default 2048).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
secs="${1:-60}"; shift || true
harnesses=("$@"); [ ${#harnesses[@]} -gt 0 ] || harnesses=(tum_list tum_trajectory rawlog)
out="${FUZZ_BUILD:-$root/build-fuzz}"
cxx="${CXX:-clang++}"
nice_n="${NICE:-19}"
mkdir -p "$out/obj"

flags=(-std=c++17 -O1 -g -fno-omit-frame-pointer -I"$root/include" -I/usr/include/opencv4 -I/usr/include/eigen3)
for m in /usr/include/mrpt/*/include; do flags+=(-I"$m"); done
libs=(-lmrpt-obs -lmrpt-maps -lmrpt-opengl -lmrpt-img -lmrpt-poses -lmrpt-math -lmrpt-serialization -lmrpt-io
      -lmrpt-config -lmrpt-system -lmrpt-containers -lmrpt-rtti -lmrpt-random -lmrpt-core
      -lopencv_imgcodecs -lopencv_imgproc -lopencv_core -lz -lpthread)
# The library sources the parsers need, instrumented for coverage.
srcs=(src/core/trajectory.cpp src/core/atomic_file.cpp src/core/camera.cpp src/io/tum_source.cpp src/io/rawlog.cpp)

build() {
  local objs=()
  for s in "${srcs[@]}"; do
    local o="$out/obj/$(basename "${s%.cpp}").o"
    if [ ! -f "$o" ] || [ "$root/$s" -nt "$o" ]; then
      echo "compiling $s" >&2
      nice -n "$nice_n" "$cxx" "${flags[@]}" -fsanitize=fuzzer-no-link,address -c "$root/$s" -o "$o"
    fi
    objs+=("$o")
  done
  for h in "${harnesses[@]}"; do
    if [ ! -x "$out/fuzz_$h" ] || [ "$here/fuzz_$h.cpp" -nt "$out/fuzz_$h" ] || [ -n "$(find "$out/obj" -newer "$out/fuzz_$h" -name '*.o')" ]; then
      echo "linking fuzz_$h" >&2
      nice -n "$nice_n" "$cxx" "${flags[@]}" -fsanitize=fuzzer,address "$here/fuzz_$h.cpp" "${objs[@]}" "${libs[@]}" -o "$out/fuzz_$h"
    fi
  done
}

build
status=0
for h in "${harnesses[@]}"; do
  corpus="$out/corpus_$h"      # grows while fuzzing; the committed seeds stay as they are
  mkdir -p "$corpus" "$out/artifacts_$h"
  cp -n "$here/corpus/$h/"* "$corpus/" 2>/dev/null || true
  dict=(); [ -f "$here/$h.dict" ] && dict=(-dict="$here/$h.dict")
  echo "== fuzz_$h for ${secs}s (corpus $corpus)" >&2
  # rss_limit: a hostile length field must not make the reader allocate gigabytes.
  # -jobs would send the output to ./fuzz-N.log: parallel runs only when asked (JOBS > 1), logs in $out.
  par=(); [ "${JOBS:-1}" -gt 1 ] && par=(-jobs="$JOBS" -workers="$JOBS")
  (cd "$out" && nice -n "$nice_n" "$out/fuzz_$h" "$corpus" "${dict[@]}" -max_total_time="$secs" -rss_limit_mb="${RSS_LIMIT_MB:-2048}" \
        -max_len=65536 "${par[@]}" -print_final_stats=1 -artifact_prefix="$out/artifacts_$h/" \
        >"$out/fuzz_$h.log" 2>&1) || true
  [ ${#par[@]} -eq 0 ] || cat "$out"/fuzz-*.log >>"$out/fuzz_$h.log"
  grep -E "^#[0-9]+ +DONE|ERROR|SUMMARY|stat::" "$out/fuzz_$h.log" >&2 || true
  if grep -qE "ERROR: (AddressSanitizer|libFuzzer)|deadly signal|SUMMARY: (Address|Undefined)" "$out/fuzz_$h.log"; then
    echo "fuzz_$h: CRASH, see $out/fuzz_$h.log and $out/artifacts_$h/" >&2
    status=1
  else
    echo "fuzz_$h: no crash in ${secs}s ($(grep -oE 'stat::number_of_executed_units: [0-9]+' "$out/fuzz_$h.log" | tail -1))" >&2
  fi
done
exit $status
