#!/usr/bin/env bash
# ThreadSanitizer over the tests that run std::threads (not part of the default build or of CI: ~15 min
# of building, and the tests run 5-20x slower). Reports go to $TSAN_OUT/<test>.<pid>. Exit 0 only when
# every test ran to its end and passed with no report. oneTBB runs on one thread (tbb_one_thread.cpp):
# TBB tasks run on their caller, so races between two TBB tasks are not looked for.
#   tests/tsan/run.sh [test...]     default: the tests below
# Env: TSAN_BUILD (default build-tsan), TSAN_OUT (default /tmp/vofusion-tsan), TIMEOUT (s a test, 1500).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
build="${TSAN_BUILD:-$root/build-tsan}"
out="${TSAN_OUT:-/tmp/vofusion-tsan}"
tests=("$@"); [ ${#tests[@]} -gt 0 ] || tests=(test_rawlog_threads test_gzip_members test_live test_loop test_reconstruction test_world_model test_live_grab_app test_task_thread test_indexed_source)
# target_clones' resolvers run before TSAN's runtime is up (a segfault at start-up): one version each.
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVOFUSION_BUILD_TESTS=ON \
  -DCMAKE_CXX_FLAGS="-fsanitize=thread -D'target_clones(...)=used'" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" \
  -DCMAKE_C_FLAGS=-fsanitize=thread \
  -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=thread -DCMAKE_SHARED_LINKER_FLAGS=-fsanitize=thread >/dev/null
export TSAN_OPTIONS="suppressions='$here/suppressions.txt' halt_on_error=0 exitcode=0"
ninja -C "$build" vofusion vofusion-grab rgbd-simulate "${tests[@]}"
g++ -O1 -shared -fPIC "$here/tbb_one_thread.cpp" -o "$build/libtbb_one_thread.so" -ltbb
mkdir -p "$out"
rm -f "$out"/test_*  # only this script's own reports (TSAN_OUT may be a folder of the user's)
status=0
for t in "${tests[@]}"; do
  echo "tsan: $t" >&2
  LD_PRELOAD="$build/libtbb_one_thread.so" TSAN_OPTIONS="$TSAN_OPTIONS log_path='$out/$t'" \
    timeout "${TIMEOUT:-1500}" "$build/bin/$t" >"$out/$t.out" 2>&1 || { echo "tsan: $t exited $? (see $out/$t.out)" >&2; status=1; }
done
reports=("$out"/test_*.[0-9]*)
if [ -e "${reports[0]}" ]; then
  echo "tsan: reports in ${reports[*]}" >&2
  exit 1
fi
[ "$status" = 0 ] && echo "tsan: no report" >&2
exit "$status"
