#!/usr/bin/env bash
# Builds the libFuzzer harnesses with clang (independent of the g++/CMake build) and runs each for a
# given time. See tests/fuzz/README.md.
#   tests/fuzz/run.sh [seconds_per_harness=60] [harness...]    harnesses: tum_list tum_trajectory rawlog
# Env: FUZZ_BUILD (default build-fuzz), LIB_BUILD (the g++ CMake build providing libvofusion.a, default
#      build), CXX (default clang++), JOBS (libFuzzer -jobs, default 1),
#      SANITIZE (default address; empty: libFuzzer alone), NICE (default 19), RSS_LIMIT_MB (libFuzzer -rss_limit_mb, also the malloc limit; default 2048, rawlog 2560).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
secs="${1:-60}"; shift || true
harnesses=("$@"); [ ${#harnesses[@]} -gt 0 ] || harnesses=(tum_list tum_trajectory rawlog)
out="${FUZZ_BUILD:-$root/build-fuzz}"
cxx="${CXX:-clang++}"
nice_n="${NICE:-19}"
san="${SANITIZE-address}"   # SANITIZE= (empty) builds without AddressSanitizer
mkdir -p "$out/obj"

flags=(-std=c++17 -O1 -g -fno-omit-frame-pointer -I"$root/include" -I/usr/include/opencv4 -I/usr/include/eigen3)
for m in /usr/include/mrpt/*/include; do flags+=(-I"$m"); done
# The parser under test is compiled here with coverage instrumentation; everything else it calls comes
# from the regular g++ build's libvofusion.a, linked with that build's own library list.
lib_build="$(cd "${LIB_BUILD:-$root/build}" && pwd)"
declare -A src_of=([tum_list]=src/io/tum_source.cpp [tum_trajectory]=src/core/trajectory.cpp [rawlog]=src/io/rawlog.cpp)

build() {
  nice -n "$nice_n" ninja -C "$lib_build" vofusion_lib rgbd-eval >&2
  local link
  link="$(ninja -C "$lib_build" -t commands rgbd-eval | tail -1)"
  link="${link#*-o bin/rgbd-eval}"; link="${link% && :}"
  for h in "${harnesses[@]}"; do
    local s="${src_of[$h]}" o="$out/obj/$h.o"
    o="$out/obj/$h${san:+-$san}.o"
    if [ ! -f "$o" ] || [ "$root/$s" -nt "$o" ] || [ "$here/run.sh" -nt "$o" ]; then
      echo "compiling $s (instrumented)" >&2
      nice -n "$nice_n" "$cxx" "${flags[@]}" -fsanitize=fuzzer-no-link${san:+,$san} -c "$root/$s" -o "$o"
    fi
    echo "linking fuzz_$h" >&2
    (cd "$lib_build" && eval nice -n "$nice_n" "$cxx" "-fsanitize=fuzzer${san:+,$san}" "$here/fuzz_$h.cpp" "${flags[*]}" \
       "$o" "$link" -o "$out/fuzz_$h")
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
  # Under ASan a request above the RSS limit fails as glibc's malloc fails on a machine without that
  # much memory (nullptr; OpenCV and operator new throw) instead of aborting: an untouched cv::Mat
  # sized from a corrupt field costs address space only (see README).
  # rawlog: MRPT keeps the buffers of up to 5 destroyed 3D observations for reuse, up to 1.6 GB when
  # corrupt entries each come close to the reader's 64 MiB buffer limit (see README).
  rss="${RSS_LIMIT_MB:-$([ "$h" = rawlog ] && echo 2560 || echo 2048)}"
  asan_opts="${ASAN_OPTIONS:-allocator_may_return_null=1:max_allocation_size_mb=$((rss - 1))}"
  (cd "$out" && ASAN_OPTIONS="$asan_opts" nice -n "$nice_n" "$out/fuzz_$h" "$corpus" "${dict[@]}" -max_total_time="$secs" -rss_limit_mb="$rss" \
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
