#!/usr/bin/env bash
# Benchmark of the 6D RGB-D odometry (issue 3) on TUM fr1_xyz (first 300 frames) with ground truth:
# ATE RMSE, RPE (1 s) and speed for the paper variant, the robust variant (the default) and each
# keypoint set alone; with EXTRA=1 also the NARF resolution / threading / keyframe choices.
#   bench/odometry.sh [build_dir] [data_dir] [max_frames]
# Speed: "fps" is wall-clock odometry-only frames per second (image loading excluded) as the app
# measures it; "cpu ms/f" is the process's user+sys CPU time per frame (includes PNG decoding),
# which stays meaningful when other jobs share the machine; "load" is the 1-minute load average
# when the row finished (fps is only comparable to the 2-core target when it is below ~2).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$root/build}"
data="${2:-$root/../shared/data/tum/rgbd_dataset_freiburg1_xyz_first300}"
frames="${3:-300}"
ninja -C "$build" rgbd-odometry >/dev/null
bin="$build/bin/rgbd-odometry"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

run() {  # name, then --set arguments
  local name="$1"; shift
  local sets=()
  for s in "$@"; do sets+=(--set "$s"); done
  local out
  if ! /usr/bin/time -f "CPU %U %S" -o "$tmp/time" "$bin" "$data" --out "$tmp/run" --no-rawlog --max-frames "$frames" \
       "${sets[@]}" >"$tmp/stdout" 2>"$tmp/stderr"; then
    echo "$name: rgbd-odometry failed: $(tail -1 "$tmp/stderr")" >&2
    failed_runs=1
    return 0
  fi
  out="$(cat "$tmp/stdout" "$tmp/time"; grep -E "per-stage" "$tmp/stderr" || true)"
  local ate rpe_t rpe_r fps failed cpu load
  ate=$(sed -n 's/^ATE rmse \([0-9.]*\) m.*/\1/p' <<<"$out")
  rpe_t=$(sed -n 's/^RPE(1s) rmse \([0-9.]*\) m  \([0-9.]*\) deg/\1/p' <<<"$out")
  rpe_r=$(sed -n 's/^RPE(1s) rmse \([0-9.]*\) m  \([0-9.]*\) deg/\2/p' <<<"$out")
  fps=$(sed -n 's/.*odometry \([0-9.]*\) fps/\1/p' <<<"$out")
  failed=$(sed -n 's/.*failed \([0-9]*\) .*/\1/p' <<<"$out")
  # Per frame done (rgbd-odometry's "frames N" line): a shorter sequence than --max-frames has fewer.
  local done_frames
  done_frames=$(sed -n 's/^frames \([0-9]*\) .*/\1/p' <<<"$out")
  cpu=$(awk '/^CPU/ {printf "%.0f", 1000*($2+$3)/'"${done_frames:-$frames}"'}' <<<"$out")
  load=$(cut -d' ' -f1 /proc/loadavg)
  printf "| %-30s | %7s | %8s | %8s | %5s | %8s | %6s | %5s |\n" "$name" "${ate:-?}" "${rpe_t:-?}" "${rpe_r:-?}" \
    "${fps:-?}" "${cpu:-?}" "${failed:-?}" "$load"
  printf "%-30s %s\n" "$name" "$(grep per-stage <<<"$out")" >>"$tmp/stages.txt"
}

failed_runs=0  # a failed run is named and the table goes on; the exit code says so at the end
echo "data: $data ($frames frames), $(nproc) cores, load at start: $(cut -d' ' -f1-3 /proc/loadavg)"
printf "| %-30s | %7s | %8s | %8s | %5s | %8s | %6s | %5s |\n" variant "ATE [m]" "RPE [m]" "RPE[deg]" fps \
  "cpu ms/f" failed load
echo "|--------------------------------|---------|----------|----------|-------|----------|--------|-------|"
run "paper (union, Algorithm 1)"   odometry.motion_method=paper
run "robust (union, default)"
run "robust, STAR only"            odometry.keypoints=star
run "robust, NARF only"            odometry.keypoints=narf
run "paper, STAR only"             odometry.keypoints=star odometry.motion_method=paper
if [ "${EXTRA:-0}" = 1 ]; then
  run "robust, NARF 1/4 res"       narf.downsample=4
  run "robust, NARF 1/8 res"       narf.downsample=8
  run "robust, NARF sequential"    odometry.narf_concurrent=false
  run "robust, previous frame only" odometry.references=1
  run "robust, no colour time"     odometry.colour_time=false
  run "robust, no Cauchy kernel"   motion.cauchy=0
  run "robust, integer STAR"       star.subpixel=false
  run "robust, no undistortion"    odometry.undistort=false
  run "robust, isotropic weights"  motion.ray_noise=false
  run "robust, keyframes (60)"     odometry.keyframe_min_inliers=60
  run "former defaults"            odometry.references=1 odometry.colour_time=false motion.cauchy=0 \
                                   motion.gauss_newton_iterations=3 star.subpixel=false
fi
echo "# per-stage wall ms/frame of each run (narf runs beside the others unless sequential):"
cat "$tmp/stages.txt"
exit "$failed_runs"
