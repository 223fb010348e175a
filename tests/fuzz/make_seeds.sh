#!/usr/bin/env bash
# Regenerates corpus/rawlog/ with make_rawlog_seeds.cpp, built with the flags of an existing CMake build.
#   tests/fuzz/make_seeds.sh [build_dir=build]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
b="$(cd "${1:-$root/build}" && pwd)"
ninja -C "$b" vofusion_lib rgbd-eval >&2
python3 - "$here" "$b" <<'PY'
import json, shlex, subprocess, sys
here, b = sys.argv[1], sys.argv[2]
cc = next(e for e in json.load(open(b + "/compile_commands.json")) if e["file"].endswith("apps/rgbd-eval.cpp"))
obj = b + "/make_rawlog_seeds.o"
args = shlex.split(cc["command"])
args[args.index("-o") + 1] = obj
args[args.index("-c") + 1] = here + "/make_rawlog_seeds.cpp"
args = [a for a in args if not a.startswith(("-MD", "-MT", "-MF"))]
subprocess.run(args, check=True, cwd=cc["directory"])
link = subprocess.run(["ninja", "-C", b, "-t", "commands", "rgbd-eval"], capture_output=True, text=True,
                      check=True).stdout.strip().splitlines()[-1]
link = link.replace("CMakeFiles/rgbd-eval.dir/apps/rgbd-eval.cpp.o", obj).replace("-o bin/rgbd-eval", "-o make_rawlog_seeds")
subprocess.run(["bash", "-c", link], check=True, cwd=b)
PY
mkdir -p "$here/corpus/rawlog"
"$b/make_rawlog_seeds" "$here/corpus/rawlog"
ls -l "$here/corpus/rawlog"
