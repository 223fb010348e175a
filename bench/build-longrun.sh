#!/usr/bin/env bash
# Builds bench/longrun against an existing CMake build's libvofusion.a, with that build's own compile
# and link flags (borrowed from the rgbd-eval app), so no CMake change is needed.
#   bench/build-longrun.sh [build_dir=build]   -> <build_dir>/bin/longrun
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
b="$(cd "${1:-$root/build}" && pwd)"
ninja -C "$b" vofusion_lib rgbd-eval >&2
python3 - "$root" "$b" <<'PY'
import json, shlex, subprocess, sys
root, b = sys.argv[1], sys.argv[2]
cc = next(e for e in json.load(open(b + "/compile_commands.json")) if e["file"].endswith("apps/rgbd-eval.cpp"))
obj = b + "/bench-longrun.o"
args = shlex.split(cc["command"])
i = args.index("-o"); args[i + 1] = obj
i = args.index("-c"); args[i + 1] = root + "/bench/longrun.cpp"
args = [a for a in args if not a.startswith(("-MD", "-MT", "-MF"))]
print("compiling bench/longrun.cpp", file=sys.stderr)
subprocess.run(args, check=True, cwd=cc["directory"])
link = subprocess.run(["ninja", "-C", b, "-t", "commands", "rgbd-eval"], capture_output=True, text=True,
                      check=True).stdout.strip().splitlines()[-1]
link = link.replace("CMakeFiles/rgbd-eval.dir/apps/rgbd-eval.cpp.o", obj).replace("-o bin/rgbd-eval", "-o bin/longrun")
print("linking bin/longrun", file=sys.stderr)
subprocess.run(["bash", "-c", link], check=True, cwd=b)
PY
echo "$b/bin/longrun"
