#!/usr/bin/env python3
"""The paper's evaluation (Figueroa et al. §4) in one command: every tracking mode of vofusion on every
sequence, with the TUM benchmark's metrics laid out as the paper's Table 1.

Called by bench/run; python3 standard library only. For each sequence (a TUM folder or a 7-Scenes
sequence folder) and each mode it runs build/bin/vofusion, measures wall time and peak RSS of the
process (wait4), reads summary.json (loop fps, per-stage ms/frame, fallbacks, lost frames), evaluates
trajectory.txt against the ground truth with rgbd-eval (ATE, RPE over 1 s) and draws the appendix
figure (top view with error vectors + translational error over time) with rgbd-eval --plot.
Writes bench/results/<sequence>.md and .json and bench/results/<sequence>/<mode>.png (a partial run:
under <build>/bench-runs/results/ instead).
"""
import argparse
import datetime
import glob
import json
import math
import os
import re
import shlex
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tables import COMMITTED as COMMITTED_RESULTS  # noqa: E402  the tables the README quotes

# name -> (vofusion --mode, INI text of the variant). "odometry" alone uses the defaults
# (union keypoints, robust motion); the variants select the keypoint set and the paper's Algorithm 1.
MODES = {
    "joint": ("joint", ""),
    "paper-handoff": ("paper-handoff", ""),
    "paper-algo1": ("paper-handoff", "[odometry]\nmotion_method = paper\n"),
    "kinfu": ("kinfu", ""),
    "odometry": ("odometry", ""),
    "odo-union-algo1": ("odometry", "[odometry]\nkeypoints = union\nmotion_method = paper\n"),
    "odo-star": ("odometry", "[odometry]\nkeypoints = star\n"),
    "odo-narf": ("odometry", "[odometry]\nkeypoints = narf\n"),
    "odo-star-algo1": ("odometry", "[odometry]\nkeypoints = star\nmotion_method = paper\n"),
}
DEFAULT_MODES = ["joint", "paper-handoff", "kinfu", "odometry"]
QUICK_MODES = ["joint", "kinfu", "odometry"]

# Synthetic sequences the benchmark renders itself (rgbd-simulate, exact ground truth) beside the real
# ones: name -> rgbd-simulate arguments.
SYNTHETIC = {
    "synthetic_room": ["--scene", "room"],
    "synthetic_corridor": ["--scene", "corridor"],
    "synthetic_bare_wall": ["--scene", "bare_wall"],
    "synthetic_shake": ["--scene", "room", "--trajectory", "shake"],
    # The same motion on another seed, the depth read row by row over 30 ms as Kinect v1 does (what
    # [kinfu] joint_rolling_shutter assumes): one shake seed alone is not a measure.
    "synthetic_shake_rs": ["--scene", "room", "--trajectory", "shake", "--seed", "2", "--depth-readout", "0.03"],
}

# Settings shared by every run: no poses.rawlog (PNG encoding would dominate the fps of the fast modes)
# and no CGAL mesh post-processing (minutes per run on 2 cores; it does not change the trajectory).
COMMON_INI = "[output]\nwrite_rawlog = false\nclean_mesh = false\n"

STATS = ["std", "median", "rmse", "mean", "p95", "max"]
STAT_LABEL = {"std": "Std", "median": "Median", "rmse": "RMS", "mean": "Mean", "p95": "95th percentile", "max": "Max"}


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def is_seven_scenes(folder):
    return bool(glob.glob(os.path.join(folder, "frame-*.depth.png")))


def rotation_to_quaternion(r):
    """3x3 rotation (row lists) -> (qx, qy, qz, qw), Shepperd's method."""
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return ((r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s, 0.25 * s)
    if r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        return (0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s, (r[2][1] - r[1][2]) / s)
    if r[1][1] > r[2][2]:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        return ((r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s, (r[0][2] - r[2][0]) / s)
    s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
    return ((r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s, (r[1][0] - r[0][1]) / s)


def seven_scenes_groundtruth(folder, out_path, fps=30.0):
    """frame-XXXXXX.pose.txt (4x4 camera-to-world) -> TUM trajectory stamped number/fps, as
    SevenScenesSource stamps its frames."""
    lines = ["# ground truth from %s (7-Scenes poses, stamps = frame number / %g Hz)" % (folder, fps)]
    for path in sorted(glob.glob(os.path.join(folder, "frame-*.pose.txt"))):
        number = int(re.search(r"frame-(\d+)\.pose\.txt$", path).group(1))
        with open(path) as f:
            v = [float(x) for x in f.read().split()]
        if len(v) != 16 or not all(math.isfinite(x) for x in v):
            continue  # unknown pose: not evaluated
        r = [v[0:3], v[4:7], v[8:11]]
        q = rotation_to_quaternion(r)
        n = math.sqrt(sum(c * c for c in q))
        lines.append("%.6f %.6f %.6f %.6f %.7f %.7f %.7f %.7f" % ((number / fps, v[3], v[7], v[11]) +
                                                                    tuple(c / n for c in q)))
    with open(out_path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return out_path


def run_timed(cmd, log_path, env=None):
    """Runs cmd with stdout+stderr to log_path; returns (exit code, wall s, peak RSS MiB) of that process."""
    with open(log_path, "w") as logf:
        t0 = time.monotonic()
        p = subprocess.Popen(cmd, stdout=logf, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(p.pid, 0)
        wall = time.monotonic() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
    return p.returncode, wall, usage.ru_maxrss / 1024.0  # Linux: KiB


def evaluate(rgbd_eval, gt, est, png):
    cmd = [rgbd_eval, gt, est, "--json", "--delta", "1.0"]
    if png:
        cmd += ["--plot", png]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        return {"error": r.stderr.strip()}
    ev = json.loads(r.stdout)
    # Over 50 ms (the next frame or the one after): the tail of bad frames, issue 30 reports its p95.
    r = subprocess.run([rgbd_eval, gt, est, "--json", "--delta", "0.05"], capture_output=True, text=True)
    if r.returncode != 0:  # the figure issue 30 asks about: a failure fails the benchmark, as the 1 s one does
        return dict(ev, error="50 ms RPE: " + r.stderr.strip())
    ev["rpe_50ms"] = json.loads(r.stdout).get("rpe")
    return ev


def write_results(res, args, command):
    res["date"] = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    res["command"] = command
    res["host"] = {"cpus": os.cpu_count(), "load_avg_at_end": os.getloadavg()}
    md = markdown(res, command, args.results)
    base = os.path.join(args.results, res["sequence"])
    for path, text in ((base + ".md", md + "\n"), (base + ".json", json.dumps(res, indent=1) + "\n")):
        tmp = path + ".tmp-%d" % os.getpid()
        with open(tmp, "w") as f:
            f.write(text)
        os.replace(tmp, path)  # whole or not at all
    return md


def sequence_name(seq):
    """The results' file name: the folder's name, and for 7-Scenes its scene's too (every scene names its
    sequences seq-01, seq-02, ...: chess/seq-01 and fire/seq-01 would share one table)."""
    folder = os.path.abspath(os.path.normpath(seq))
    name = os.path.basename(folder)
    if is_seven_scenes(folder):
        name = os.path.basename(os.path.dirname(folder)) + "_" + name
    return name


def run_sequence(seq, args, command):
    name = sequence_name(seq)
    work = os.path.join(args.work, name)
    fig_dir = os.path.join(args.results, name)
    os.makedirs(work, exist_ok=True)
    os.makedirs(fig_dir, exist_ok=True)
    seven = is_seven_scenes(seq)
    gt = (seven_scenes_groundtruth(seq, os.path.join(work, "groundtruth.txt")) if seven
          else os.path.join(seq, "groundtruth.txt"))
    gt = os.path.normpath(gt) if os.path.exists(gt) else None
    result = {"sequence": name, "path": os.path.abspath(seq), "layout": "7-Scenes" if seven else "TUM",
              "groundtruth": gt, "max_frames": args.max_frames, "modes": {}}
    for mode in args.modes:
        vmode, ini = MODES[mode]
        out = os.path.join(work, mode)
        cfg = os.path.join(work, mode + ".ini")
        with open(cfg, "w") as f:
            f.write(COMMON_INI + ini)
        cmd = [args.vofusion, seq, "--out", out, "--mode", vmode, "--config", cfg]
        if args.max_frames:
            cmd += ["--max-frames", str(args.max_frames)]
        if seven and args.intrinsics:
            cmd += ["--intrinsics", args.intrinsics]
        log("[%s] %s ..." % (name, mode))
        code, wall, rss = run_timed(["nice", "-n", str(args.nice)] + cmd if args.nice else cmd,
                                    os.path.join(work, mode + ".log"))
        entry = {"command": " ".join(shlex.quote(c) for c in cmd), "config": ini, "exit_code": code,
                 "wall_s": wall, "peak_rss_mib": rss}
        if code != 0:
            with open(os.path.join(work, mode + ".log")) as f:
                entry["error"] = f.read().strip().splitlines()[-1:]
            log("[%s] %s FAILED: %s" % (name, mode, entry["error"]))
            result["modes"][mode] = entry
            result["complete"] = mode == args.modes[-1]
            write_results(result, args, command)
            continue
        with open(os.path.join(out, "summary.json")) as f:
            s = json.load(f)
        entry["frames"] = s.get("frames")
        entry["loop_fps"] = s.get("fps")
        entry["process_fps"] = s.get("frames", 0) / wall if wall > 0 else None
        entry["stages"] = s.get("stages", {})
        entry["lost_frames"] = s.get("lost_frames")
        entry["icp_fallbacks_to_odometry"] = s.get("icp_fallbacks_to_odometry")
        entry["predicted_frames"] = s.get("predicted_frames", 0)
        entry["odometry_failures"] = s.get("odometry_failures")
        entry["summary_peak_memory_mib"] = s.get("peak_memory_mib")
        entry["fusion"] = s.get("fusion")
        entry["mesh"] = s.get("mesh")
        if gt:
            png = os.path.join(fig_dir, mode + ".png")
            entry["eval"] = evaluate(args.rgbd_eval, gt, os.path.join(out, "trajectory.txt"), png)
            if "error" not in entry["eval"]:
                entry["figure"] = os.path.relpath(png, args.results)
            else:
                log("[%s] %s: evaluation FAILED: %s" % (name, mode, entry["eval"]["error"]))
        result["modes"][mode] = entry
        # Written after every mode: an interrupted benchmark keeps what it measured.
        result["complete"] = mode == args.modes[-1]
        write_results(result, args, command)
        ev = entry.get("eval", {})
        log("[%s] %s: %s frames, %.1f fps (loop), ATE RMSE %s m, fallbacks %s, lost %s, %.0f MiB" % (
            name, mode, entry["frames"], entry["loop_fps"] or 0,
            "%.4f" % ev["ate_m"]["rmse"] if "ate_m" in ev else "-", entry["icp_fallbacks_to_odometry"],
            entry["lost_frames"], rss))
    return result


def synthetic_sequences(args):
    """Renders the synthetic sequences into <build>/bench-synthetic/ (kept while their arguments and the
    simulator hold)."""
    simulate = os.path.join(args.build, "bin", "rgbd-simulate")
    if not os.access(simulate, os.X_OK):  # its size and time stamp the renders, cached or not
        sys.exit("bench: %s is not built (ninja -C %s rgbd-simulate), or --no-synthetic" % (simulate, args.build))
    root = os.path.join(args.build, "bench-synthetic")
    os.makedirs(root, exist_ok=True)
    seqs = []
    for name, extra in SYNTHETIC.items():
        folder = os.path.join(root, name)
        cmd = [simulate, "--out", folder, "--frames", str(args.synthetic_frames)] + extra
        stamp = os.path.join(root, name + ".cmd")
        # The simulator's size and time too: a rebuilt rgbd-simulate renders anew (its earlier renders
        # passed for this build's, with the same command line).
        st = os.stat(simulate)
        made_by = " ".join(cmd) + "\n%d %d" % (st.st_size, st.st_mtime_ns)
        if not (os.path.exists(stamp) and open(stamp).read() == made_by and os.path.isdir(folder)):
            log("[%s] rendering: %s" % (name, " ".join(cmd)))
            if os.path.exists(folder):
                subprocess.run(["rm", "-rf", folder], check=True)
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
            with open(stamp, "w") as f:
                f.write(made_by)
        seqs.append(folder)
    return seqs


def summary_markdown(results, modes, command, of=None):
    """One row per sequence, one column per mode: ATE RMSE [m] and (lost / fallbacks / odometry failures).
    `of`: the sequences the run was given; fewer results (an interrupted run) are marked partial."""
    partial = of is not None and len(results) < of
    L = ["# Summary: ATE RMSE [m] per sequence and mode", ""] + (
        ["**Partial: %d of %d sequences** (the run was interrupted or is still going; the rows of the others "
         "are not here)." % (len(results), of), ""] if partial else []) + [
         "Produced by `%s` on %s. Cell: ATE RMSE, then (lost frames / ICP fallbacks to the odometry / "
         "frames predicted at constant velocity). Frame-loop fps below each sequence's row." % (
             command, datetime.datetime.now().strftime("%Y-%m-%d %H:%M")), "",
         "| sequence | " + " | ".join(modes) + " |", "|---|" + "---|" * len(modes)]
    for res in results:
        cells, fps = [], []
        for m in modes:
            e = res["modes"].get(m)
            if not e or e.get("exit_code") != 0:
                cells.append("n/a")
                fps.append("-")
                continue
            ate = ((e.get("eval") or {}).get("ate_m") or {}).get("rmse")
            cells.append("%s (%s / %s / %s)" % (fmt(ate), e.get("lost_frames"), e.get("icp_fallbacks_to_odometry"),
                                               e.get("predicted_frames", 0)))
            fps.append(fmt(e.get("loop_fps"), 1))
        L.append("| %s | %s |" % (res["sequence"], " | ".join(cells)))
        L.append("| &nbsp;&nbsp;fps | %s |" % " | ".join(fps))
    return "\n".join(L) + "\n"


def fmt(v, digits=4):
    return "-" if v is None else ("%.*f" % (digits, v))


def markdown(res, command, results_dir):
    modes = list(res["modes"])
    ok = [m for m in modes if res["modes"][m].get("exit_code") == 0]
    L = []
    L.append("# %s (%s)" % (res["sequence"], res["layout"]))
    L.append("")
    L.append("Produced by `%s` on %s. Frames: %s. Ground truth: `%s`." % (
        command, res["date"], res["max_frames"] or "all", res["groundtruth"] or "none"))
    if not res.get("complete", True):
        L.append("")
        L.append("**Partial:** the benchmark was still running or was stopped; only the modes below were measured.")
    L.append("")
    L.append("Modes (vofusion `--mode` + config): " + "; ".join(
        "`%s` = `%s`%s" % (m, MODES[m][0], (" + `" + MODES[m][1].strip().replace("\n", " ") + "`") if MODES[m][1] else "")
        for m in modes) + ". Every run: `" + COMMON_INI.strip().replace("\n", " ") + "`.")
    L.append("")
    head = "| | " + " | ".join(modes) + " |"
    sep = "|---|" + "---|" * len(modes)

    def table(title, key, sub, digits):
        L.append("**%s**" % title)
        L.append("")
        L.append(head)
        L.append(sep)
        for st in STATS:
            row = []
            for m in modes:
                ev = res["modes"][m].get("eval") or {}
                node = ev.get(key) if sub is None else (ev.get(key) or {}).get(sub)
                row.append(fmt(node.get(st) if node else None, digits))
            L.append("| %s | %s |" % (STAT_LABEL[st], " | ".join(row)))
        L.append("")

    if res["groundtruth"]:
        L.append("## Table 1 layout: trajectory errors")
        L.append("")
        table("Absolute trajectory error, translational [m]", "ate_m", None, 4)
        table("Relative pose error (1 s), translational [m]", "rpe", "trans_m", 4)
        table("Relative pose error (1 s), rotational [deg]", "rpe", "rot_deg", 3)
        table("Relative pose error (50 ms), translational [m]", "rpe_50ms", "trans_m", 4)

    L.append("## Speed, memory, tracking")
    L.append("")
    L.append(head)
    L.append(sep)

    def row(label, f):
        L.append("| %s | %s |" % (label, " | ".join(f(res["modes"][m]) for m in modes)))

    row("frames", lambda e: str(e.get("frames", "-")))
    row("fps, frame loop", lambda e: fmt(e.get("loop_fps"), 2))
    row("fps, whole process", lambda e: fmt(e.get("process_fps"), 2))
    row("wall time [s]", lambda e: fmt(e.get("wall_s"), 1))
    row("peak RSS [MiB]", lambda e: fmt(e.get("peak_rss_mib"), 0))
    row("ICP fallbacks to odometry", lambda e: str(e.get("icp_fallbacks_to_odometry", "-")))
    row("predicted frames (constant velocity)", lambda e: str(e.get("predicted_frames", "-")))
    row("lost frames", lambda e: str(e.get("lost_frames", "-")))
    row("odometry failures", lambda e: str(e.get("odometry_failures", "-")))
    row("volume shifts", lambda e: str((e.get("fusion") or {}).get("volume_shifts", "-")))
    row("mesh faces / vertices", lambda e: "%d / %d" % (e["mesh"]["faces"], e["mesh"]["vertices"]) if e.get("mesh") else "-")
    stages = []
    for m in ok:
        for st in res["modes"][m].get("stages", {}):
            if st not in stages:
                stages.append(st)
    for st in stages:
        row("stage `%s` ms/frame" % st,
            lambda e, st=st: fmt(((e.get("stages") or {}).get(st) or {}).get("ms_per_frame"), 1))
    L.append("")
    failed = [m for m in modes if m not in ok]
    for m in failed:
        L.append("- `%s` failed (exit %s): %s" % (m, res["modes"][m]["exit_code"], res["modes"][m].get("error")))
    for m in ok:
        if "error" in (res["modes"][m].get("eval") or {}):
            L.append("- `%s`: evaluation failed: %s" % (m, res["modes"][m]["eval"]["error"]))
    figs = [(m, res["modes"][m]["figure"]) for m in ok if res["modes"][m].get("figure")]
    if figs:
        L.append("## Figures")
        L.append("")
        L.append("Top view of ground truth, aligned estimate and error vectors (left) and translational "
                 "error over time (right), per mode (PNG, not committed; regenerate with the command above):")
        L.append("")
        for m, f in figs:
            L.append("- `%s`: `%s`" % (m, os.path.relpath(os.path.join(results_dir, f), ROOT)))
        L.append("")
    return "\n".join(L)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequences", nargs="*",
                    help="TUM or 7-Scenes folders (default: ../shared/data/tum/* and the synthetic scenes)")
    ap.add_argument("--modes", default=None,
                    help="comma-separated subset of: %s (default: %s)" % (", ".join(MODES), ",".join(DEFAULT_MODES)))
    ap.add_argument("--max-frames", type=int, default=0)
    ap.add_argument("--synthetic-frames", type=int, default=300, help="length of the rendered synthetic sequences")
    ap.add_argument("--no-synthetic", action="store_true", help="default sequences: the real ones only")
    ap.add_argument("--quick", action="store_true",
                    help="a fast check: %s, 100 frames of every sequence" % ",".join(QUICK_MODES))
    ap.add_argument("--build", default=os.environ.get("VOFUSION_BUILD", os.path.join(ROOT, "build")))
    ap.add_argument("--results", default=None,
                    help="where the tables go (default: bench/results for a full run; <work>/results for --quick, "
                         "--max-frames or a --modes subset, which must not replace the committed tables)")
    ap.add_argument("--work", default=None, help="run outputs (default <build>/bench-runs)")
    ap.add_argument("--intrinsics", default=None, help="7-Scenes only: override the default 585/320/240")
    ap.add_argument("--nice", type=int, default=0, help="run vofusion under nice -n N")
    args = ap.parse_args()
    if args.quick:
        args.modes = args.modes or ",".join(QUICK_MODES)
        args.max_frames = args.max_frames or 100
        args.synthetic_frames = min(args.synthetic_frames, 100)
    args.modes = [m.strip() for m in (args.modes or ",".join(DEFAULT_MODES)).split(",") if m.strip()]
    for m in args.modes:
        if m not in MODES:
            ap.error("unknown mode '%s' (known: %s)" % (m, ", ".join(MODES)))
    args.vofusion = os.path.join(args.build, "bin", "vofusion")
    args.rgbd_eval = os.path.join(args.build, "bin", "rgbd-eval")
    for exe in (args.vofusion, args.rgbd_eval):
        if not os.access(exe, os.X_OK):
            ap.error("%s is not built (ninja -C %s vofusion rgbd-eval)" % (exe, args.build))
    args.work = args.work or os.path.join(args.build, "bench-runs")
    shared = os.path.join(ROOT, "..", "shared", "data", "tum")
    # Without ../shared the default run lacks the TUM rows: partial, or it replaced the committed summary.
    partial = (args.max_frames or not set(DEFAULT_MODES) <= set(args.modes) or args.synthetic_frames != 300
               or args.no_synthetic or (not args.sequences and not os.path.isdir(shared)))
    if args.results is None:
        args.results = os.path.join(args.work, "results") if partial else COMMITTED_RESULTS
        if partial:
            log("a partial run (--quick, --max-frames, a --modes subset, --no-synthetic, no ../shared): tables go to %s, "
                "not bench/results (--results DIR to choose)" % args.results)
    seqs = args.sequences or sorted(d for d in glob.glob(os.path.join(shared, "*")) if os.path.isdir(d))
    if not args.sequences and not args.no_synthetic:
        seqs += synthetic_sequences(args)
    if not seqs:
        ap.error("no sequences given and none under ../shared/data/tum/")
    command = "bench/run " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    os.makedirs(args.results, exist_ok=True)
    results = []
    for seq in seqs:
        if not os.path.isdir(seq):
            ap.error("%s: no such folder" % seq)
        res = run_sequence(seq, args, command)
        results.append(res)
        print(write_results(res, args, command))
        # The summary after every sequence: an interrupted benchmark keeps what it measured. In bench/results
        # only a run over the default sequences writes it: one over some would leave their rows alone there.
        summary = summary_markdown(results, args.modes, command, of=len(seqs))
        if args.sequences and os.path.abspath(args.results) == COMMITTED_RESULTS:
            continue
        for path, text in ((os.path.join(args.results, "summary.md"), summary),
                           (os.path.join(args.results, "summary.json"),
                            json.dumps({"command": command, "modes": args.modes, "partial": len(results) < len(seqs),
                                        "sequences": [
                                {"sequence": r["sequence"], "modes": {m: {k: e.get(k) for k in (
                                    "frames", "loop_fps", "lost_frames", "icp_fallbacks_to_odometry", "predicted_frames",
                                    "odometry_failures")} | {"ate_rmse_m": ((e.get("eval") or {}).get("ate_m") or {}).get("rmse")}
                                    for m, e in r["modes"].items()}} for r in results]}, indent=1) + "\n")):
            tmp = path + ".tmp-%d" % os.getpid()
            with open(tmp, "w") as f:
                f.write(text)
            os.replace(tmp, path)
    print(summary)
    # A mode that failed, or whose trajectory could not be evaluated, fails the benchmark (after it wrote
    # everything it measured).
    failures = [(r["sequence"], m) for r in results for m, e in r["modes"].items()
                if e.get("exit_code") != 0 or "error" in (e.get("eval") or {})]
    for seq, m in failures:
        print("bench/run: %s, mode %s failed (see its results)" % (seq, m), file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
