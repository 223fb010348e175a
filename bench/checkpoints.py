#!/usr/bin/env python3
"""Checkpoints on a shared sequence (issue 32's test at full length):

    bench/run --checkpoints [--sequence DIR] [--build DIR] [--every S]

1. The cost: the same sequence with --checkpoint-every S (default 5) against none, back to back: frame-loop
   seconds, checkpoints written, seconds spent writing them (the plain run also gives the frame count).
2. A clean run of the whole sequence (default config, mesh on) with a checkpoint after every frame; the
   checkpoint is copied as the run passes 50 %, 90 % and 99 % of the frames, as a kill would leave it.
3. Each copy resumed (`vofusion <seq> --out o --checkpoint-every 1e-6 --resume copy`, the clean run's own
   command): trajectory.txt, mesh.ply and poses.rawlog compared byte for byte with the clean run's.
4. A run killed (-9) after a third of the frames while checkpointing, resumed, compared the same way.
5. The last checkpoint's size.
Writes bench/results/checkpoints.md.
"""
import argparse
import filecmp
import json
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import tables  # noqa: E402
KIND = b"VOFUSION-CHECKPOINT-"


def checkpoint_magic():
    """The header the source writes (run_session.cpp's kCheckpointMagic): a copy here went stale at version 2."""
    src = os.path.join(os.path.dirname(HERE), "src", "pipeline", "run_session.cpp")
    m = re.search(r'kCheckpointMagic\[\] = "(VOFUSION-CHECKPOINT-[0-9]+)\\n"', open(src).read())
    if not m:
        sys.exit("bench checkpoints: no kCheckpointMagic in " + src)
    return m.group(1).encode() + b"\n"


MAGIC = checkpoint_magic()


class OtherVersion(Exception):
    """A checkpoint whose header this script does not read."""


def log(msg):
    print("[bench checkpoints] " + msg, file=sys.stderr, flush=True)


def checkpoint_frames(path):
    """Frames processed before the checkpoint at path (its header), None when there is none."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MAGIC) + 4)
            if len(head) < len(MAGIC) + 4 or not head.startswith(MAGIC):
                if head.startswith(KIND) and b"\n" in head and not head.startswith(MAGIC):
                    raise OtherVersion("%s: %s, not %s (a build older than the source?)"
                                       % (path, head[:head.index(b"\n")].decode(), MAGIC.decode().strip()))
                return None
            (n,) = struct.unpack("<I", head[len(MAGIC):])
            f.seek(len(MAGIC) + 4 + n)
            (frames,) = struct.unpack("<Q", f.read(8))
            return frames
    except (OSError, struct.error):
        return None


def vofusion(build, seq, out, extra):
    return [os.path.join(build, "bin", "vofusion"), seq, "--out", out] + extra


def run(cmd):
    t = time.time()
    p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        sys.exit("failed: " + " ".join(cmd) + "\n" + p.stderr[-2000:])
    return time.time() - t


def same_outputs(a, b):
    return {f: filecmp.cmp(os.path.join(a, f), os.path.join(b, f), shallow=False)
            for f in ("trajectory.txt", "mesh.ply", "poses.rawlog")}


def summary(d):
    with open(os.path.join(d, "summary.json")) as f:
        return json.load(f)


def main():
    root = os.path.dirname(HERE)
    # argparse: an unknown or misspelt option (--sequence=DIR, --evry) is an error, not the default run.
    ap = argparse.ArgumentParser(prog="bench/run --checkpoints", allow_abbrev=False)
    ap.add_argument("--checkpoints", action="store_true")
    ap.add_argument("--sequence", default=os.path.join(root, "..", "shared", "data", "tum", "rgbd_dataset_freiburg1_xyz_first300"))
    ap.add_argument("--build", default=os.environ.get("VOFUSION_BUILD", os.path.join(root, "build")))
    ap.add_argument("--every", default="5", help="s between checkpoints in the cost comparison")
    a = ap.parse_args(sys.argv[1:])
    seq, build, every = a.sequence, os.path.abspath(a.build), a.every
    work = os.path.join(build, "bench-checkpoints")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    each = ["--checkpoint-every", "0.000001"]

    # The cost first: its plain run says how many frames vofusion makes of the sequence (rgb.txt's lines
    # overcount where a depth image has no colour within 0.02 s, and a checkpoint counting to them never came).
    # The sequence is read once before, so that neither of the pair reads it from a cold disk.
    for folder, _, files in os.walk(seq):
        for name in files:
            with open(os.path.join(folder, name), "rb") as f:
                while f.read(1 << 20):
                    pass
    log("cost: --checkpoint-every %s against none, back to back" % every)
    cost = []
    for label, extra in (("none", []), ("every %s s" % every, ["--checkpoint-every", every])):
        out = os.path.join(work, "cost_" + label.replace(" ", "_"))
        run(vofusion(build, seq, out, extra))
        s = summary(out)
        c = s.get("checkpoints", {})
        cost.append((label, s.get("frames"), s.get("seconds", 0.0), c.get("written", 0), c.get("seconds_writing", 0.0)))
    total = int(cost[0][1] or 0)
    if total < 3:
        sys.exit("bench checkpoints: %s gave %d frames, too few to checkpoint and resume" % (seq, total))

    clean = os.path.join(work, "clean")
    targets = [total // 2, total * 9 // 10, total * 99 // 100]
    kept = []
    failed = []
    done = threading.Event()

    def watch():
        path = os.path.join(clean, "checkpoint")
        for target in targets:
            while not done.is_set():
                try:
                    n = checkpoint_frames(path)
                except OtherVersion as e:
                    failed.append(str(e))
                    return
                if n is not None and n >= target:
                    copy = os.path.join(work, "at%d" % target)
                    try:
                        with open(path, "rb") as src, open(copy, "wb") as dst:
                            shutil.copyfileobj(src, dst)
                    except OSError:
                        continue
                    if (checkpoint_frames(copy) or 0) >= target:
                        kept.append((checkpoint_frames(copy), copy))
                        break
                time.sleep(0.002)

    log("clean run, %d frames, a checkpoint after every frame" % total)
    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:  # a failed run (sys.exit), a missing program or Ctrl-C: the watcher stops too
        clean_s = run(vofusion(build, seq, clean, each))
    finally:
        done.set()
        watcher.join()
    if failed:
        sys.exit("bench checkpoints: " + failed[0])
    if len(kept) < len(targets):
        sys.exit("bench checkpoints: the clean run left %d of the %d checkpoints to copy" % (len(kept), len(targets)))
    rows = []
    for frames, copy in kept:
        log("resuming from frame %d" % frames)
        out = copy + "_out"
        secs = run(vofusion(build, seq, out, each + ["--resume", copy]))
        rows.append(("checkpoint at frame %d (%.0f %%)" % (frames, 100.0 * frames / total), secs, same_outputs(clean, out)))

    killed = os.path.join(work, "killed")
    log("killed run")
    p = subprocess.Popen(vofusion(build, seq, killed, each), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while (checkpoint_frames(os.path.join(killed, "checkpoint")) or 0) < total // 3 and p.poll() is None:
        time.sleep(0.001)
    p.send_signal(signal.SIGKILL)
    p.wait()
    at = checkpoint_frames(os.path.join(killed, "checkpoint"))
    if at is None:
        sys.exit("bench checkpoints: the killed run left no checkpoint (it ended before a third of the frames?)")
    secs = run(vofusion(build, seq, killed, each + ["--resume", os.path.join(killed, "checkpoint")]))
    rows.append(("killed (-9), its last checkpoint at frame %d" % at, secs, same_outputs(clean, killed)))

    # The last checkpoint's size: the one a run with checkpoints leaves when interrupted at its end.
    size_run = os.path.join(work, "size")
    p = subprocess.Popen(vofusion(build, seq, size_run, each), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while (checkpoint_frames(os.path.join(size_run, "checkpoint")) or 0) < total - 1 and p.poll() is None:
        time.sleep(0.002)
    p.send_signal(signal.SIGKILL)
    p.wait()
    if (checkpoint_frames(os.path.join(size_run, "checkpoint")) or 0) < total - 1:
        sys.exit("bench checkpoints: the size run ended before its checkpoint reached frame %d" % (total - 1))
    size_mib = os.path.getsize(os.path.join(size_run, "checkpoint")) / 2**20

    lines = ["# Checkpoints: %s" % os.path.basename(os.path.normpath(seq)), "",
             "Command: `bench/run --checkpoints` (bench/checkpoints.py); default config, mesh on.", "",
             "Clean run with a checkpoint after every frame: %.1f s. Each resumed run below is the same command with "
             "`--resume <checkpoint>`, compared byte for byte with the clean run." % clean_s, "",
             "| resumed from | run time (s) | trajectory.txt | mesh.ply | poses.rawlog |", "|---|---|---|---|---|"]
    for label, secs, same in rows:
        lines.append("| %s | %.1f | %s | %s | %s |" % (label, secs, *["identical" if same[f] else "**differs**"
                                                                     for f in ("trajectory.txt", "mesh.ply", "poses.rawlog")]))
    lines += ["", "Cost (same sequence, back to back):", "",
              "| checkpoints | frames | frame loop (s) | written | writing them (s) |", "|---|---|---|---|---|"]
    for label, frames, secs, written, writing in cost:
        lines.append("| %s | %s | %.1f | %d | %.2f |" % (label, frames, secs, written, writing))
    lines += ["", "A checkpoint at frame %d holds %.1f MiB." % (total - 1, size_mib)]
    # Another sequence or spacing than the committed table's: beside the run, not over the table.
    full = (os.path.realpath(a.sequence) == os.path.realpath(ap.get_default("sequence")) and
            float(a.every) == float(ap.get_default("every")))
    results = tables.results_dir(full, build)
    os.makedirs(results, exist_ok=True)
    with open(os.path.join(results, "checkpoints.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    log("table written to " + os.path.join(results, "checkpoints.md"))
    if not all(all(same.values()) for _, _, same in rows):
        sys.exit(1)


if __name__ == "__main__":
    main()
