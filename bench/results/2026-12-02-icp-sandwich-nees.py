#!/usr/bin/env python3
"""The consistency check of bench/results/2026-12-02-icp-sandwich-covariance.md: for each pair of
consecutive frames, the camera centre's relative-motion error against ground truth, tested against the
sum of the two frames' centre covariances (NEES), for each covariance the measuring build printed.

Usage: 2026-12-02-icp-sandwich-nees.py RUN_DIR INPUT_DIR STDERR_OF_THE_RUN
(a run of 2026-12-02-icp-sandwich-covariance.diff with VOF_SW=1 VOF_NOCOV=1: its stderr holds one "SW"
line per frame, the timestamp, ICP's inliers, then 3x3 covariances, row by row, one per column below).
TUM files are read with bench/loops.py's helpers.
"""
import bisect
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from loops import read_tum, relative_position, rotate  # noqa: E402

COLUMNS = ["joint", "T8", "T16", "T32", "T64"]  # the tracker's own, then tiles of T pixels


def covariances(err_path):
    """{timestamp: [3x3 per column]} from the run's SW lines."""
    out = {}
    with open(err_path) as f:
        for line in f:
            if not line.startswith("SW "):
                continue
            v = line.split()
            nums = [float(x) for x in v[3:]]
            out[round(float(v[1]), 4)] = [[nums[9 * k + 3 * i:9 * k + 3 * i + 3] for i in range(3)]
                                          for k in range(len(nums) // 9)]
    return out


def nearest(poses, stamps, t, tolerance=0.02):
    """The pose of `poses` (read_tum's) nearest to t, None when none is within `tolerance` seconds."""
    k = bisect.bisect_left(stamps, t)
    best = min((s for s in stamps[max(0, k - 1):k + 1]), key=lambda s: abs(s - t), default=None)
    return poses[best] if best is not None and abs(best - t) < tolerance else None


def inverse3(m):
    (a, b, c), (d, e, f), (g, h, i) = m
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if abs(det) < 1e-30:
        return None
    return [[(e * i - f * h) / det, (c * h - b * i) / det, (b * f - c * e) / det],
            [(f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det],
            [(d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det]]


def main(run, inp, err):
    est = read_tum(os.path.join(run, "trajectory.txt"))
    gt = read_tum(os.path.join(inp, "groundtruth.txt"))
    gt_stamps = sorted(gt)
    cov = covariances(err)
    nees = {c: [] for c in COLUMNS}
    traces = {c: [] for c in COLUMNS}
    squared_errors = []
    stamps = sorted(est)
    for ta, tb in zip(stamps, stamps[1:]):
        ga, gb = nearest(gt, gt_stamps, ta), nearest(gt, gt_stamps, tb)
        if not (cov.get(ta) and cov.get(tb) and ga and gb):
            continue
        de, dg = relative_position(est[ta], est[tb]), relative_position(ga, gb)
        e = rotate(est[ta][1], [de[i] - dg[i] for i in range(3)])  # the estimate's world frame
        squared_errors.append(sum(x * x for x in e))
        for k, c in enumerate(COLUMNS):
            s = [[cov[ta][k][i][j] + cov[tb][k][i][j] for j in range(3)] for i in range(3)]
            si = inverse3(s) if s[0][0] > 0 else None
            if not si:
                continue
            nees[c].append(sum(e[i] * si[i][j] * e[j] for i in range(3) for j in range(3)))
            traces[c].append(s[0][0] + s[1][1] + s[2][2])
    mean_e2 = sum(squared_errors) / max(1, len(squared_errors))
    line = "%s pairs %d rms_err_mm %.2f" % (os.path.basename(run.rstrip("/")), len(squared_errors), 1000 * math.sqrt(mean_e2))
    for c in COLUMNS:
        if nees[c]:
            median = sorted(nees[c])[len(nees[c]) // 2]
            scale = math.sqrt(mean_e2 / (sum(traces[c]) / len(traces[c])))
            line += " | %s nees_med %.1f scale %.2f" % (c, median, scale)
    print(line)


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:4])
