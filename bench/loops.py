#!/usr/bin/env python3
"""Loop closure on the synthetic loop scene (one lap round a block), seeds 1-5 at 300 and 900 frames:

    bench/run --loops [--seeds 1,2,3,4,5] [--lengths 300,900] [--build DIR]

For each recording one vofusion run (default config, [output] mesh = false: only the path is measured).
Loop closure never feeds back into tracking, so the run's trajectory_tracked.txt is the run without
loop closure and trajectory.txt the run with it. Reported per run: ATE RMSE of both, loops accepted and
kept, the largest loop's error against the truth, and the lap's end: where the path comes back to its
start (the nearest pair of frames, one in its first fifth and one in its last), the later pose's position
relative to the earlier one, against the truth's (m). Writes bench/results/loops.md and loops.json.
"""
import json
import math
import os
import shutil
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import machine  # noqa: E402
import tables  # noqa: E402


def log(msg):
    print("[bench loops] " + msg, file=sys.stderr, flush=True)


def read_tum(path):
    """{timestamp: (t, q)} of a TUM trajectory file; q = (x, y, z, w)."""
    poses = {}
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            v = [float(x) for x in line.split()]
            poses[round(v[0], 4)] = (v[1:4], v[4:8])
    return poses


def rotate(q, v):
    """v rotated by the unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q
    tx, ty, tz = 2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])
    return [v[0] + w * tx + (y * tz - z * ty), v[1] + w * ty + (z * tx - x * tz), v[2] + w * tz + (x * ty - y * tx)]


def conj(q):
    return (-q[0], -q[1], -q[2], q[3])


def relative_position(a, b):
    """Position of pose b in pose a's camera frame."""
    (ta, qa), (tb, _) = a, b
    return rotate(conj(qa), [tb[i] - ta[i] for i in range(3)])


def lap_end_error(gt_path, est_path):
    """m: where the lap closes (the frame of its first fifth and the frame of its last fifth nearest each
    other in the truth), the later one's position relative to the earlier, estimate against truth."""
    gt, est = read_tum(gt_path), read_tum(est_path)
    stamps = sorted(set(gt) & set(est))
    n = len(stamps)
    if n < 10:
        return None
    def dist(a, b):
        return math.sqrt(sum((gt[a][0][i] - gt[b][0][i]) ** 2 for i in range(3)))
    _, first, last = min((dist(a, b), a, b) for a in stamps[:n // 5] for b in stamps[n - n // 5:])
    g = relative_position(gt[first], gt[last])
    e = relative_position(est[first], est[last])
    return math.sqrt(sum((g[i] - e[i]) ** 2 for i in range(3)))


def render(build, root, seed, frames):
    path = os.path.join(root, "loop_s%d_f%d.rawlog" % (seed, frames))
    simulate = os.path.join(build, "bin", "rgbd-simulate")
    if not os.access(simulate, os.X_OK):
        sys.exit("bench loops: %s is not built (ninja -C %s rgbd-simulate)" % (simulate, build))
    # Rendered again when the simulator was rebuilt (its size and time in a stamp beside the rawlog):
    # an older rgbd-simulate's render passed for this build's.
    st = os.stat(simulate)
    made_by, stamp = "%s %d %d" % (simulate, st.st_size, st.st_mtime_ns), path + ".made-by"
    if not (os.path.exists(path) and os.path.exists(stamp) and open(stamp).read() == made_by):
        # --overwrite: a rawlog deleted to force a new render leaves its images and ground truth beside it,
        # which rgbd-simulate would not replace.
        cmd = [simulate, "--scene", "loop", "--seed", str(seed), "--frames", str(frames), "--out", path, "--overwrite"]
        p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if p.returncode != 0:
            sys.exit("bench loops: rendering %s failed: %s" % (path, p.stderr.strip()[-2000:]))
        with open(stamp, "w") as f:
            f.write(made_by)
    return path


def run_one(build, rawlog, out, config):
    # This run's outputs only: an earlier run's trajectory_tracked.txt (written only with loop closure on)
    # was read as this run's path without loop closure.
    shutil.rmtree(out, ignore_errors=True)
    cmd = [os.path.join(build, "bin", "vofusion"), rawlog, "--out", out, "--config", config]
    t0 = time.monotonic()
    with open(out + ".log", "w") as logf:
        code = subprocess.run(cmd, stdout=logf, stderr=subprocess.STDOUT).returncode
    wall = time.monotonic() - t0
    if code != 0:
        return {"error": "exit %d, see %s.log" % (code, out)}
    s = json.load(open(os.path.join(out, "summary.json")))
    gt = rawlog[:-len(".rawlog")] + ".groundtruth.txt"
    loops = s.get("loops", [])
    lc = s.get("loop_closure", {})
    return {
        "ate_without": s.get("ate_tracked", {}).get("rmse"),
        "ate_with": s.get("ate", {}).get("rmse"),
        "loops_accepted": len(loops),
        "loops_kept": sum(1 for l in loops if l.get("active")),
        "max_loop_error_m": max([l.get("error_vs_ground_truth_m", 0) for l in loops], default=None),
        "lap_end_without_m": lap_end_error(gt, os.path.join(out, "trajectory_tracked.txt"))
        if os.path.exists(os.path.join(out, "trajectory_tracked.txt")) else None,  # loop closure off: none
        "lap_end_with_m": lap_end_error(gt, os.path.join(out, "trajectory.txt")),
        "loop_thread_ms_per_frame": lc.get("thread_ms_per_frame"),
        "loop_thread_cpu_ms_per_frame": lc.get("thread_cpu_ms_per_frame"),
        "frame_loop_fps": s.get("fps"),
        "wall_s": wall,
    }


def fmt(v, digits=4):
    return "-" if v is None else ("%." + str(digits) + "f") % v


def markdown(rows, command):
    out = ["# Loop closure on the loop scene", "", "`%s`, %s" % (command, time.strftime("%Y-%m-%d %H:%M")), "",
           "Machine: " + machine.describe() + ".", "",
           "Without = the run's tracked trajectory (loop closure never feeds back into tracking). Lap end: where "
           "the path comes back to its start, the later pose's position relative to the earlier, against the truth. "
           "Loop thread: wall time of its stages (it shares two cores with the frame loop's two threads, so it also "
           "counts waiting for a core) / its CPU time, per frame. Mean row: ratio of the means (mean of the ratios).", "",
           "| frames | seed | ATE without (m) | ATE with (m) | with / without | loops kept / accepted | largest loop error (m) "
           "| lap end without (m) | lap end with (m) | loop thread ms/frame, wall / CPU |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            out.append("| %d | %d | %s |" % (r["frames"], r["seed"], r["error"]))
            continue
        ratio = r["ate_with"] / r["ate_without"] if r["ate_with"] and r["ate_without"] else None
        out.append("| %d | %d | %s | %s | %s | %d / %d | %s | %s | %s | %s / %s |" % (
            r["frames"], r["seed"], fmt(r["ate_without"]), fmt(r["ate_with"]), fmt(ratio, 2), r["loops_kept"],
            r["loops_accepted"], fmt(r["max_loop_error_m"]), fmt(r["lap_end_without_m"]), fmt(r["lap_end_with_m"]),
            fmt(r["loop_thread_ms_per_frame"], 2), fmt(r.get("loop_thread_cpu_ms_per_frame"), 2)))
    for frames in sorted({r["frames"] for r in rows}):
        ok = [r for r in rows if r["frames"] == frames and "error" not in r and r["ate_with"] and r["ate_without"]]
        if ok:
            mw = sum(r["ate_with"] for r in ok) / len(ok)
            mo = sum(r["ate_without"] for r in ok) / len(ok)
            mr = sum(r["ate_with"] / r["ate_without"] for r in ok) / len(ok)
            out.append("| %d | mean (lap end: worst) | %s | %s | %s (%s) | | | | %s | |" % (
                frames, fmt(mo), fmt(mw), fmt(mw / mo, 2), fmt(mr, 2), fmt(max((r["lap_end_with_m"] for r in ok if r["lap_end_with_m"] is not None), default=None))))
    return "\n".join(out) + "\n"


def main(argv):
    import argparse
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(prog="bench/run --loops", allow_abbrev=False)
    ap.add_argument("--loops", action="store_true")
    ap.add_argument("--seeds", default="1,2,3,4,5")
    ap.add_argument("--lengths", default="300,900")
    ap.add_argument("--build", default=os.environ.get("VOFUSION_BUILD", os.path.join(os.path.dirname(here), "build")))
    ap.add_argument("--config", default=None, help="an INI whose sections are added to the benchmark's own")
    ap.add_argument("--results", default=None,
                    help="where the tables go (default: bench/results for the full run; <build>/bench-runs/results "
                         "for a subset of seeds or lengths or with --config, which must not replace the committed tables)")
    ap.add_argument("--name", default="loops", help="results file name (bench/results/<name>.md)")
    args = ap.parse_args(argv)
    if args.results is None:
        ints = lambda text: sorted(int(x) for x in text.split(","))
        full = (ints(args.seeds) == ints(ap.get_default("seeds")) and ints(args.lengths) == ints(ap.get_default("lengths"))
                and not args.config)
        args.results = tables.results_dir(full, args.build)
    root = os.path.join(args.build, "bench-synthetic")
    work = os.path.join(args.build, "bench-loops")
    os.makedirs(root, exist_ok=True)
    os.makedirs(work, exist_ok=True)
    config = os.path.join(work, "bench.ini")
    with open(config, "w") as f:
        f.write("[output]\nmesh = false\nwrite_rawlog = false\n")
        if args.config:
            f.write(open(args.config).read())
    rows = []
    for frames in [int(x) for x in args.lengths.split(",")]:
        for seed in [int(x) for x in args.seeds.split(",")]:
            rawlog = render(args.build, root, seed, frames)
            r = run_one(args.build, rawlog, os.path.join(work, "s%d_f%d" % (seed, frames)), config)
            r.update({"seed": seed, "frames": frames})
            log("%d frames, seed %d: %s" % (frames, seed, json.dumps(r)))
            rows.append(r)
    command = "bench/run " + " ".join(argv)
    md = markdown(rows, command)
    os.makedirs(args.results, exist_ok=True)
    for path, text in ((os.path.join(args.results, args.name + ".md"), md),
                       (os.path.join(args.results, args.name + ".json"), json.dumps(rows, indent=1) + "\n")):
        tmp = path + ".tmp-%d" % os.getpid()
        with open(tmp, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    print(md)
    log("tables written to " + args.results)
    failed = [r for r in rows if "error" in r]
    if failed:  # the table lists them; the exit code tells a script
        log("%d of %d runs failed" % (len(failed), len(rows)))
        sys.exit(1)


if __name__ == "__main__":
    main(sys.argv[1:])
