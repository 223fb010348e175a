#!/usr/bin/env python3
"""Real time on two cores, back to back against an earlier build (issue 31's figures):

    bench/run --realtime [--baseline REV] [--build DIR] [--sequences DIR,DIR] [--rounds N]

For each shared sequence, the earlier build and this one run one after the other, N rounds (default 3)
in alternating order, and each figure is the median of its rounds (this machine's speed drifts by
~25 %: only runs side by side in time compare, and one pair of 100-frame runs can come out either way):
  - `vofusion <seq> --out o` (default config): frame-loop fps (summary.json; builds without
    seconds_before_frames, 618a78c's among them, counted the end's work in it: their progress line at
    the loop's end), end-to-end fps (frames /
    wall time of the process, to the last output written), the start-up before the first frame, the
    time from the last frame to the last output against the frame loop's (and its parts: summary.json
    output_seconds, where the build writes it), ATE RMSE, peak RSS;
  - `vofusion-grab --replay <seq> --out o --live --no-gui` (recording included, at the recorded rate):
    frames processed of those played;
  - the same replay of the sequence as an uncompressed rawlog with its images inside (`tum2rawlog
    --embed-images` by this build, then gunzipped): the recording then encodes each colour PNG and
    compresses each depth as it does for a real sensor, where a TUM folder's replay copies its PNGs. Reading
    such a frame costs ~2 ms of CPU, less than a TUM folder's PNG decoding (~5 ms); gzipped, ~13 ms.
The earlier build (default 618a78c, the build issue 31 was filed on) is checked out with `git worktree`
and built (apps only) under <build>/bench-baseline/, once. Writes bench/results/realtime.md.
"""
import argparse
import gzip
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import machine  # noqa: E402
import tables  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def log(msg):
    print("[bench realtime] " + msg, file=sys.stderr, flush=True)


def run_timed(cmd, log_path):
    """(exit code, wall s, peak RSS MiB) of cmd, its output to log_path."""
    with open(log_path, "w") as f:
        t0 = time.monotonic()
        p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(p.pid, 0)
        return os.waitstatus_to_exitcode(status), time.monotonic() - t0, usage.ru_maxrss / 1024.0


def baseline_build(rev, build):
    base = os.path.join(build, "bench-baseline")
    # Named by the commit, not the name given: HEAD~1 or a branch names another commit after new ones.
    p = subprocess.run(["git", "-C", ROOT, "rev-parse", "--verify", rev + "^{commit}"], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("bench realtime: --baseline %s: not a commit of this repository" % rev)
    commit = p.stdout.strip()
    src, out = os.path.join(base, "src-" + commit), os.path.join(base, "build-" + commit)
    bins = [os.path.join(out, "bin", a) for a in ("vofusion", "vofusion-grab")]
    if all(os.path.exists(b) for b in bins):
        return os.path.join(out, "bin")
    os.makedirs(base, exist_ok=True)
    if not os.path.exists(src):
        subprocess.run(["git", "-C", ROOT, "worktree", "add", "-f", "--detach", src, commit], check=True)
    log("building %s (apps only) in %s" % (rev, out))
    subprocess.run(["cmake", "-S", src, "-B", out, "-G", "Ninja", "-DCMAKE_BUILD_TYPE=Release", "-DVOFUSION_BUILD_TESTS=OFF"],
                   check=True, stdout=subprocess.DEVNULL)
    subprocess.run(["cmake", "--build", out, "-j2", "--target", "vofusion", "vofusion-grab"], check=True, stdout=subprocess.DEVNULL)
    return os.path.join(out, "bin")


def offline(bin_dir, seq, out):
    shutil.rmtree(out, ignore_errors=True)
    rc, wall, rss = run_timed([os.path.join(bin_dir, "vofusion"), seq, "--out", out], out + ".log")
    if rc != 0:
        sys.exit("vofusion failed, see " + out + ".log")
    with open(os.path.join(out, "summary.json")) as f:
        s = json.load(f)
    frames, loop_s, loop_fps = s["frames"], s["seconds"], s["fps"]
    # Start-up is neither the frame loop nor the time after its last frame. Builds before summary.json
    # had seconds_before_frames: the wall time of `vofusion --help` (libraries loaded, no input opened).
    startup, by_help = s.get("seconds_before_frames"), False
    if startup is None:
        startup, by_help = help_seconds(bin_dir, out + ".help.log"), True
        # Those builds' `seconds` and `fps` (618a78c's too) also held what came after the frame loop
        # (rec.finish(), the loop-closed re-fusion, --save-volume); their progress line at the loop's end
        # did not: its fps (0.1 fps steps, ~0.4 % at 25 fps) gives the frame loop.
        loop_fps = frame_loop_fps_in_log(out + ".log")
        if loop_fps is None:
            sys.exit("bench realtime: no frame-loop progress line in %s (its summary's fps counts the end's work)" % (out + ".log"))
        loop_s = frames / loop_fps
    # The tail's parts, where the build says them (summary.json output_seconds): mesh.ply's holds the meshing.
    parts = {o["file"]: o["seconds_since_previous"] for o in s.get("output_seconds", [])}
    return {"loop_fps": loop_fps, "e2e_fps": frames / wall, "loop_s": loop_s, "startup_s": startup, "startup_by_help": by_help,
            "tail_s": wall - startup - loop_s, "ate": s.get("ate", {}).get("rmse"), "rss": rss, "frames": frames,
            "rpe_p95": s.get("rpe_50ms", {}).get("trans_m", {}).get("p95"),
            "tail_mesh_s": parts.get("mesh.ply"), "tail_scene_s": parts.get("scene.3Dscene"),
            "tail_picture_s": parts.get("mesh.png")}


def frame_loop_fps_in_log(log_path):
    """The fps of vofusion's progress line at the frame loop's end ("vofusion [joint] 100 frames in 4s
    (23.5 fps)"), the first such line (a re-fusion's comes after it); None without one."""
    with open(log_path, errors="replace") as f:
        for line in f:
            m = re.match(r"vofusion \[[a-z-]+\] \d+ frames in \S+ \(([0-9.]+) fps\)", line.split("\r")[-1])
            if m and float(m.group(1)) > 0:
                return float(m.group(1))
    return None


_help_seconds = {}


def help_seconds(bin_dir, log_path):
    """Median wall time of three `vofusion --help`, once per build."""
    if bin_dir not in _help_seconds:
        runs = [run_timed([os.path.join(bin_dir, "vofusion"), "--help"], log_path) for _ in range(3)]
        if any(rc != 0 for rc, _, _ in runs):
            sys.exit("vofusion --help failed, see " + log_path)
        _help_seconds[bin_dir] = sorted(wall for _, wall, _ in runs)[1]
    return _help_seconds[bin_dir]


# Live runs of the baseline that failed and were run again (618a78c's image-path race fails one run of a
# few: "cannot load external range image"); this build's failures end the bench.
baseline_reruns = []


def live(bin_dir, seq, out, rerun_failed=False):
    shutil.rmtree(out, ignore_errors=True)
    cmd = [os.path.join(bin_dir, "vofusion-grab"), "--replay", seq, "--out", out, "--live", "--no-gui"]
    rc, _, _ = run_timed(cmd, out + ".log")
    if rc != 0 and rerun_failed:
        failed_log = "%s.failed-%d.log" % (out, len(baseline_reruns) + 1)
        shutil.copyfile(out + ".log", failed_log)
        baseline_reruns.append(failed_log)
        log("%s failed (see %s): run again" % (" ".join(cmd[:3]), failed_log))
        shutil.rmtree(out, ignore_errors=True)
        rc, _, _ = run_timed(cmd, out + ".log")
    if rc != 0:
        sys.exit("vofusion-grab failed, see " + out + ".log")
    kv = dict(l.split(": ", 1) for l in open(os.path.join(out, "grab-summary.txt")).read().splitlines() if ": " in l)
    return {"played": int(kv["frames_played"]), "processed": int(kv["frames_processed"])}


def sensor_rawlog(bin_dir, seq, path):
    """The sequence as an uncompressed rawlog with its images inside, made anew by this build's tum2rawlog."""
    packed = path + ".gz.rawlog"
    rc, _, _ = run_timed([os.path.join(bin_dir, "tum2rawlog"), seq, packed, "--embed-images", "--overwrite"], path + ".log")
    if rc != 0:
        sys.exit("tum2rawlog failed, see " + path + ".log")
    with gzip.open(packed, "rb") as src, open(path, "wb") as dst:  # MRPT reads a plain rawlog as well
        shutil.copyfileobj(src, dst, 1 << 20)
    os.remove(packed)
    if os.path.exists(path + ".gz.groundtruth.txt"):  # tum2rawlog's companion (a sequence with ground truth);
        os.remove(path + ".gz.groundtruth.txt")       # the rawlog holds the ground truth too
    return path


def tail_parts(r):
    """'meshing / scene / picture' seconds of the tail, or "-" for a build whose summary has no output_seconds."""
    parts = (r["tail_mesh_s"], r["tail_scene_s"], r["tail_picture_s"])
    return "-" if all(x is None for x in parts) else " / ".join("-" if x is None else "%.2f" % x for x in parts)


def fmt4(x):
    """A figure to 4 decimals, or "-" where there is none (a sequence without ground truth has no ATE)."""
    return "-" if x is None else "%.4f" % x


def median(values):
    """The median (of an even count, the mean of the middle two) of the values that are not None, or None."""
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def round_ratio(pairs, key):
    """Median of the rounds' this / base ratios (only runs side by side in time compare); "-" if none."""
    r = median(t[key] / b[key] for b, t in pairs if b[key] and t[key] is not None)
    return "-" if r is None else "%.2fx" % r


def live_row(rounds, processed, played, share):
    """'processed / played (share %)' of the round whose share is the median (the lower of two): one
    round's three figures, which medians taken apart could mix."""
    r = sorted(rounds, key=lambda x: x[share])[(len(rounds) - 1) // 2]
    return "%d / %d (%.0f %%)" % (r[processed], r[played], 100.0 * r[share])


def medians(runs):
    """Each figure's median over the rounds, peak RSS the largest."""
    out = {}
    for key, value in runs[0].items():
        if key == "rss":
            out[key] = max(r[key] for r in runs)
        elif isinstance(value, bool):
            out[key] = value
        elif isinstance(value, int):  # a count: one round's (an even number of rounds gave x.5, shown as x)
            out[key] = statistics.median_low(r[key] for r in runs)
        else:
            out[key] = median(r[key] for r in runs)
    return out


def main():
    # argparse: an unknown or misspelt option (--round 5, --baseline=REV) is an error, not the default run.
    tum = os.path.join(ROOT, "..", "shared", "data", "tum")
    ap = argparse.ArgumentParser(prog="bench/run --realtime", allow_abbrev=False)
    ap.add_argument("--realtime", action="store_true")
    ap.add_argument("--build", default=os.environ.get("VOFUSION_BUILD", os.path.join(ROOT, "build")))
    ap.add_argument("--baseline", default="618a78c", help="the revision to compare with (built once, by its commit)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--sequences", default=",".join(os.path.join(tum, d) for d in (
        "rgbd_dataset_freiburg1_xyz_first300", "rgbd_dataset_freiburg1_rpy_first100")))
    a = ap.parse_args(sys.argv[1:])
    build, rev, rounds, seqs = os.path.abspath(a.build), a.baseline, a.rounds, a.sequences.split(",")
    if rounds < 1:
        sys.exit("--rounds: at least 1")
    # This build's apps brought up to date first: a stale binary's fps was reported as HEAD's.
    log("bringing %s's apps up to date" % build)
    subprocess.run(["cmake", "--build", build, "-j2", "--target", "vofusion", "vofusion-grab", "tum2rawlog"], check=True,
                   stdout=subprocess.DEVNULL)
    builds = [(rev, baseline_build(rev, build)), ("this build", os.path.join(build, "bin"))]
    work = os.path.join(build, "bench-realtime")
    os.makedirs(work, exist_ok=True)
    head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    lines = ["# Real time, back to back: %s against this build (%s)" % (rev, head), "",
             "Command: `bench/run --realtime` (bench/realtime.py); default config, 2 cores. Each sequence is run by "
             "both builds one after the other, %d rounds in alternating order; each figure is the median of the "
             "rounds (peak RSS: the largest). End to end: frames / wall time of the process to its last output; "
             "start-up: from the process's start to the first frame (summary.json `seconds_before_frames`; for a "
             "build without it, the wall time of `vofusion --help`); tail: from the last frame to the last output "
             "(wall time minus start-up and frame loop). Live: `vofusion-grab --replay <seq> --live --no-gui`, "
             "recording included, frames processed of those played; as a sensor records it: the same replay of the "
             "sequence as an uncompressed rawlog with its images inside (`tum2rawlog --embed-images`, gunzipped), so "
             "the recording encodes each colour PNG and compresses each depth, as for a real sensor (a TUM folder's "
             "PNGs are copied); reading such a frame costs ~2 ms of CPU, a TUM folder's PNG decoding ~5 ms." % rounds, "", "Machine: " + machine.describe() + ".", ""]
    for seq in seqs:
        name = os.path.basename(os.path.normpath(seq))
        as_sensor = sensor_rawlog(builds[1][1], seq, os.path.join(work, name + "_sensor.rawlog"))
        runs = {label: [] for label, _ in builds}
        for k in range(rounds):
            for label, bins in (builds if k % 2 == 0 else builds[::-1]):
                tag = "base" if label == rev else "this"
                log("%s: %s offline, round %d of %d" % (name, label, k + 1, rounds))
                r = offline(bins, seq, os.path.join(work, "%s_%s" % (name, tag)))
                log("%s: %s live, round %d of %d" % (name, label, k + 1, rounds))
                r.update(live(bins, seq, os.path.join(work, "%s_%s_live" % (name, tag)), rerun_failed=label == rev))
                log("%s: %s live as a sensor records, round %d of %d" % (name, label, k + 1, rounds))
                sensor = live(bins, as_sensor, os.path.join(work, "%s_%s_live_sensor" % (name, tag)), rerun_failed=label == rev)
                r.update({"sensor_played": sensor["played"], "sensor_processed": sensor["processed"]})
                r["tail_share"] = r["tail_s"] / r["loop_s"]
                # Each round's own shares (a ratio of two medians mixed rounds).
                r["live_share"] = r["processed"] / r["played"]
                r["sensor_share"] = r["sensor_processed"] / r["sensor_played"]
                runs[label].append(r)
        res = {label: medians(rs) for label, rs in runs.items()}
        b, t = res[rev], res["this build"]
        pairs = list(zip(runs[rev], runs["this build"]))
        ratio = lambda k: round_ratio(pairs, k)
        startup = lambda r: "%.2f%s" % (r["startup_s"], " (`--help`)" if r["startup_by_help"] else "")
        lines += ["## %s (%d frames)" % (name, t["frames"]), "",
                  "| | %s | this build | this / %s | target |" % (rev, rev), "|---|---:|---:|---:|---|",
                  "| frame loop, fps | %.1f | %.1f | %s | >= 30 and >= 1.3x |" % (b["loop_fps"], t["loop_fps"], ratio("loop_fps")),
                  "| frame loop fps of the rounds | %s | %s | | |" % (
                      " ".join("%.1f" % r["loop_fps"] for r in runs[rev]),
                      " ".join("%.1f" % r["loop_fps"] for r in runs["this build"])),
                  "| end to end, fps | %.1f | %.1f | %s | |" % (b["e2e_fps"], t["e2e_fps"], ratio("e2e_fps")),
                  "| start-up before the first frame, s | %s | %s | | |" % (startup(b), startup(t)),
                  "| tail after the last frame, s (share of the frame loop: the median of the rounds' own shares) | %.1f (%.0f %%) | %.1f (%.0f %%) | | <= 25 %% |" % (
                      b["tail_s"], 100 * b["tail_share"], t["tail_s"], 100 * t["tail_share"]),
                  "| tail's parts, s: meshing to mesh.ply / scene.3Dscene / mesh.png after it (summary.json output_seconds) | %s | %s | | |" % (
                      tail_parts(b), tail_parts(t)),
                  "| live: processed / played (the round of the median share) | %s | %s | | >= 95 %% |" % (
                      live_row(runs[rev], "processed", "played", "live_share"),
                      live_row(runs["this build"], "processed", "played", "live_share")),
                  "| live as a sensor records it (colour PNG encoded, depth compressed): processed / played | %s | %s | | >= 95 %% |" % (
                      live_row(runs[rev], "sensor_processed", "sensor_played", "sensor_share"),
                      live_row(runs["this build"], "sensor_processed", "sensor_played", "sensor_share")),
                  "| ATE RMSE, m | %s | %s | %s | within +2 %% |" % (fmt4(b["ate"]), fmt4(t["ate"]), ratio("ate")),
                  "| RPE over 50 ms, translation p95, m (summary.json rpe_50ms) | %s | %s | %s | |" % (
                      fmt4(b["rpe_p95"]), fmt4(t["rpe_p95"]), ratio("rpe_p95")),
                  "| peak RSS, MiB | %.0f | %.0f | | <= 700 |" % (b["rss"], t["rss"]), ""]
    if baseline_reruns:  # said below the tables, with the failed runs' logs
        lines += ["Live runs of %s that failed and were run again: %d (%s)." % (
            rev, len(baseline_reruns), ", ".join(os.path.relpath(x, build) for x in baseline_reruns)), ""]
    # Another baseline, round count or sequence list than the committed table's: beside the run.
    commit = lambda rev: subprocess.run(["git", "-C", ROOT, "rev-parse", "--verify", rev + "^{commit}"],
                                        capture_output=True, text=True).stdout.strip()
    paths = lambda text: [os.path.realpath(x) for x in text.split(",")]
    full = (commit(a.baseline) == commit(ap.get_default("baseline")) and a.rounds == ap.get_default("rounds") and
            paths(a.sequences) == paths(ap.get_default("sequences")))
    results = tables.results_dir(full, build)
    os.makedirs(results, exist_ok=True)
    with open(os.path.join(results, "realtime.md"), "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))
    log("table written to " + os.path.join(results, "realtime.md"))


if __name__ == "__main__":
    main()
