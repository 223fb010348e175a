#!/usr/bin/env python3
"""One table from many vofusion runs: every folder under <dir> holding a summary.json or a vofusion.log
(scripts/batch writes one per recording) becomes a row. Python 3 standard library only.

  bench/collect.py <dir> [--json | --csv] [--jobs <dir>/jobs.tsv]

Markdown by default. --jobs: exactly the batch's folders, in its order (folder<TAB>recording per line,
as scripts/batch writes it), so a job that never started is a row too. Status: ok, interrupted, or
failed with the log's last line; a folder's exit_code (written by scripts/batch-job) decides over an
earlier run's summary.json left in place.
"""
import argparse
import csv
import json
import os
import sys

COLUMNS = [  # key, Markdown header
    ("recording", "recording"),
    ("mode", "mode"),
    ("frames", "frames"),
    ("fps", "fps"),
    ("ate_rmse_m", "ATE RMSE [m]"),
    ("lost_frames", "lost"),
    ("fallbacks", "fallbacks"),
    ("peak_rss_mib", "peak RSS [MiB]"),
    ("mesh_faces", "mesh faces"),
    ("status", "status"),
]


def last_line(path):
    """The log's last non-empty line (progress lines end in \\r, so split on both)."""
    try:
        with open(path, errors="replace") as f:
            text = f.read()
    except OSError:
        return "no log"
    lines = [l.strip() for l in text.replace("\r", "\n").split("\n") if l.strip()]
    return lines[-1] if lines else "empty log"


def first_line(path):
    """The log's first line, or "" (no log)."""
    try:
        with open(path, errors="replace") as f:
            return f.readline()
    except OSError:
        return ""


def row(folder, name, recording=None):
    r = {key: None for key, _ in COLUMNS}
    r["recording"] = name
    r["input"] = recording
    r["folder"] = folder
    summary_path = os.path.join(folder, "summary.json")
    log_path = os.path.join(folder, "vofusion.log")
    code = None
    try:
        with open(os.path.join(folder, "exit_code")) as f:
            code = int(f.read().strip())
    except (OSError, ValueError):
        pass
    s = None
    if os.path.exists(summary_path):
        try:
            with open(summary_path) as f:
                s = json.load(f)
        except (OSError, ValueError) as e:
            r["status"] = "failed: %s: %s" % (summary_path, e)
            return r
    # 130, 143: stopped by SIGINT, SIGTERM, with what was built written (unless before the first frame)
    stopped_early = code in (130, 143) and "nothing written" in last_line(log_path)
    # A batch's job (recording given, or a log batch-job began: a Slurm array collected without
    # --jobs) without an exit code never finished (killed): a summary.json there is an earlier run's.
    # A folder of a plain vofusion run has none and is judged by its summary.
    unfinished_job = code is None and (recording is not None or first_line(log_path).startswith("batch-job: "))
    if s is not None and code in (None, 0, 130, 143) and not stopped_early and not unfinished_job:
        r["input"] = r["input"] or s.get("input")
        r["mode"] = s.get("mode")
        r["frames"] = s.get("frames")
        r["fps"] = s.get("fps")
        r["ate_rmse_m"] = (s.get("ate") or {}).get("rmse")
        r["lost_frames"] = s.get("lost_frames")
        r["fallbacks"] = s.get("icp_fallbacks_to_odometry")
        r["peak_rss_mib"] = s.get("peak_memory_mib")
        r["mesh_faces"] = (s.get("mesh") or {}).get("faces")
        if s.get("interrupted") or code in (130, 143):
            r["status"] = "interrupted" + (" (%s)" % s["stop_signal"] if s.get("stop_signal") else "")
        else:
            r["status"] = "ok"
    elif not os.path.isdir(folder):
        r["status"] = "failed: not run"
    elif code is None and not os.path.exists(log_path):
        r["status"] = "failed: no summary.json and no vofusion.log"
    elif unfinished_job:
        r["status"] = "failed: the job did not finish (no exit code): %s" % last_line(log_path)
    else:
        r["status"] = "failed%s: %s" % ("" if code is None else " (exit %d)" % code, last_line(log_path))
    return r


def find_runs(root):
    runs = []
    for folder, dirs, files in os.walk(root):
        dirs.sort()
        if "summary.json" in files or "vofusion.log" in files:
            name = os.path.relpath(folder, root)
            runs.append((folder, os.path.basename(os.path.abspath(root)) if name == "." else name, None))
    return runs


def cell(key, v):
    if v is None:
        return "-"
    if key == "fps":
        return "%.1f" % v
    if key == "ate_rmse_m":
        return "%.4f" % v
    if key == "peak_rss_mib":
        return "%.0f" % v
    return str(v).replace("|", "\\|")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.error = lambda msg: sys.exit("collect: %s (see --help)" % msg)  # bad arguments: one line
    ap.add_argument("dir")
    fmt = ap.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true")
    fmt.add_argument("--csv", action="store_true")
    ap.add_argument("--jobs", help="folder<TAB>recording per line (scripts/batch's jobs.tsv)")
    args = ap.parse_args()

    if not os.path.isdir(args.dir):
        sys.exit("collect: %s: no such folder" % args.dir)
    if args.jobs:
        try:
            with open(args.jobs) as f:
                pairs = [l.rstrip("\n").split("\t", 1) for l in f if l.strip()]
        except OSError as e:
            sys.exit("collect: %s: %s" % (args.jobs, e.strerror))
        if any(len(p) != 2 for p in pairs):
            sys.exit("collect: %s: expected <folder><TAB><recording> on every line" % args.jobs)
        runs = [(os.path.join(args.dir, name), name, rec) for name, rec in pairs]
    else:
        runs = find_runs(args.dir)
    if not runs:
        sys.exit("collect: %s: no summary.json or vofusion.log under it" % args.dir)
    rows = [row(*run) for run in runs]

    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
    elif args.csv:
        w = csv.DictWriter(sys.stdout, fieldnames=[k for k, _ in COLUMNS] + ["input"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    else:
        print("| " + " | ".join(h for _, h in COLUMNS) + " |")
        print("|" + "|".join("---" if k in ("recording", "mode", "status") else "---:" for k, _ in COLUMNS) + "|")
        for r in rows:
            print("| " + " | ".join(cell(k, r[k]) for k, _ in COLUMNS) + " |")
        ok = sum(r["status"] == "ok" for r in rows)
        print("\n%d of %d runs ok." % (ok, len(rows)))


if __name__ == "__main__":
    main()
