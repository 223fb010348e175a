#!/bin/sh
# Builds a benchmark/driver source against libvofusion with exactly the flags of the project's own
# test executables (CMake does not build bench/). Usage: bench/fusion_build.sh <src.cpp> <out> [build-dir]
set -e
src=$(realpath "$1"); out=$(realpath -m "$2")
root=$(cd "$(dirname "$0")/.." && pwd)
build=$(realpath "${3:-$root/build-fusion}")
ninja -C "$build" -j2 vofusion_lib test_fusion >/dev/null
python3 - "$build" "$src" "$out" <<'PY'
import json, shlex, subprocess, sys
build, src, out = sys.argv[1:]
cmds = json.load(open(f"{build}/compile_commands.json"))
cc = next(c for c in cmds if c["file"].endswith("tests/test_fusion.cpp"))
args = shlex.split(cc["command"])
i = args.index("-c"); args[i + 1] = src
o = args.index("-o"); args[o + 1] = out + ".o"
subprocess.check_call(args, cwd=cc["directory"])
link = subprocess.check_output(["ninja", "-C", build, "-t", "commands", "bin/test_fusion"], text=True).strip().splitlines()[-1]
link = link.split("&&")[1]
parts = [p for p in shlex.split(link) if "CMakeFiles/test_fusion.dir" not in p and "gtest" not in p]
o = parts.index("-o"); parts[o + 1] = out
parts.insert(o, out + ".o")
subprocess.check_call(parts, cwd=build)
PY
