#!/usr/bin/env bash
# Benchmark of the KinectFusion stage (issue 4) through the whole app on TUM fr1_xyz (first 300 frames):
# per mode ATE/RPE, frame-loop fps (summary.json's: frames over the frame loop's seconds), per-stage
# ms/frame, peak memory and mesh size, from each run's summary.json. The machine's load average is printed: stage times are wall clock, so a loaded machine
# inflates them.
#   bench/fusion.sh [build_dir] [data_dir] [max_frames (0: every frame)] [extra vofusion args...]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$root/build}"
data="${2:-$root/../shared/data/tum/rgbd_dataset_freiburg1_xyz_first300}"
frames="${3:-300}"
shift $(( $# < 3 ? $# : 3 ))
ninja -C "$build" vofusion >/dev/null
limit=()
[ "$frames" = 0 ] || limit=(--max-frames "$frames")  # vofusion takes no --max-frames 0
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

echo "data: $data ($frames frames), $(nproc) cores, load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
failed=0
for mode in paper kinfu odometry; do
  "$build/bin/vofusion" "$data" --out "$tmp/$mode" --mode "$mode" "${limit[@]}" "$@" >"$tmp/$mode.log" 2>&1 ||
    { echo "$mode: vofusion failed: $(tail -1 "$tmp/$mode.log")"; failed=1; continue; }
done
python3 - "$tmp" <<'PY'
import json, os, sys
tmp = sys.argv[1]
stages = ["odometry", "preprocess", "icp", "integrate", "raycast", "shift", "total"]
head = f"{'mode':9} {'ATE[m]':>7} {'RPE[m]':>7} {'RPE[deg]':>8} {'fps':>5} " + " ".join(f"{s[:9]:>9}" for s in stages) + \
       f" {'peak MiB':>8} {'tsdf MiB':>8} {'faces':>8} {'fallback':>8} {'lost':>5}"
print("per-stage columns: ms/frame (wall clock)")
print(head)
for mode in ["paper", "kinfu", "odometry"]:
    p = os.path.join(tmp, mode, "summary.json")
    if not os.path.exists(p):
        continue
    s = json.load(open(p))
    ate = s.get("ate", {}).get("rmse", float("nan"))
    rpe = s.get("rpe", {})
    rt = rpe.get("trans_m", {}).get("rmse", float("nan"))
    rr = rpe.get("rot_deg", {}).get("rmse", float("nan"))
    st = s.get("stages", {})
    cols = " ".join(f"{st[k]['ms_per_frame']:9.1f}" if k in st else f"{'-':>9}" for k in stages)
    print(f"{mode:9} {ate:7.4f} {rt:7.4f} {rr:8.3f} {s.get('fps', 0):5.1f} {cols} {s.get('peak_memory_mib', 0):8.0f} "
          f"{s.get('fusion', {}).get('tsdf_memory_mib', 0):8.0f} {s.get('mesh', {}).get('faces', 0):8d} "
          f"{s.get('icp_fallbacks_to_odometry', 0):8d} {s.get('lost_frames', 0):5d}")
PY
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
exit "$failed"
