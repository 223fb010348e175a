#!/usr/bin/env bash
# Benchmark of the 6D RGB-D odometry (issue 3) on TUM fr1_xyz (first 300 frames) with ground truth:
# ATE RMSE, RPE (1 s) and speed for the paper variant, the robust variant and each keypoint set alone,
# then the NARF resolution / threading choices.
#   bench/odometry.sh [build_dir] [data_dir] [max_frames]
# Speed: "fps" is wall-clock odometry-only frames per second (image loading excluded) as the app
# measures it; "cpu ms/f" is the process's user+sys CPU time per frame (includes PNG decoding),
# which stays meaningful when other jobs share the machine.
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
  local t0 t1 out
  out="$( { /usr/bin/time -f "CPU %U %S" "$bin" "$data" --out "$tmp/$name" --no-rawlog --max-frames "$frames" \
          "${sets[@]}" 2>&1 1>&3 | grep -E "^CPU|per-stage" ; } 3>&1 )"
  local ate rpe_t rpe_r fps failed cpu stages
  ate=$(sed -n 's/^ATE rmse \([0-9.]*\) m.*/\1/p' <<<"$out")
  rpe_t=$(sed -n 's/^RPE(1s) rmse \([0-9.]*\) m  \([0-9.]*\) deg/\1/p' <<<"$out")
  rpe_r=$(sed -n 's/^RPE(1s) rmse \([0-9.]*\) m  \([0-9.]*\) deg/\2/p' <<<"$out")
  fps=$(sed -n 's/.*odometry \([0-9.]*\) fps/\1/p' <<<"$out")
  failed=$(sed -n 's/.*failed \([0-9]*\) .*/\1/p' <<<"$out")
  cpu=$(awk '/^CPU/ {printf "%.1f", 1000*($2+$3)/'"$frames"'}' <<<"$out")
  printf "%-34s %8s %9s %9s %7s %8s %7s\n" "$name" "${ate:-?}" "${rpe_t:-?}" "${rpe_r:-?}" "${fps:-?}" "${cpu:-?}" "${failed:-?}"
  grep "per-stage" <<<"$out" | sed 's/^/    /' >>"$tmp/stages.txt"
}

echo "data: $data ($frames frames), $(nproc) cores"
printf "%-34s %8s %9s %9s %7s %8s %7s\n" variant "ATE[m]" "RPE[m]" "RPE[deg]" fps "cpu ms/f" failed
run "paper (union, Algorithm 1)"       odometry.motion_method=paper
run "robust (union)"                   odometry.motion_method=robust
run "robust, STAR only"                odometry.keypoints=star
run "robust, NARF only"                odometry.keypoints=narf
run "paper, STAR only"                 odometry.keypoints=star odometry.motion_method=paper
run "paper, NARF only"                 odometry.keypoints=narf odometry.motion_method=paper
echo "# NARF resolution and threading (robust, union)"
run "narf 1/2 res (320x240)"           narf.downsample=2
run "narf 1/8 res (80x60)"             narf.downsample=8
run "narf 1/4, max 50 points"          narf.max_points=50
run "narf 1/4, sequential"             odometry.narf_concurrent=false
echo "# per-stage ms/frame of each run, in order:"
cat "$tmp/stages.txt"
