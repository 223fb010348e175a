#!/usr/bin/env python3
"""Does a change carry over? The rule a default must pass, as one command (the developers' guide, "how to
choose a default"): it wins by more than 1 mm on each half of both shared sequences, each half run on its
own, and on the synthetic set over several seeds, never on one.

    bench/run --rules --baseline OTHER_BUILD [--build DIR] [--config INI] [--candidate INI] [--seeds 1,2,3,4,5]
                      [--perturb N]
    bench/run --rules --baseline build --candidate new_value.ini     # one key's new value, same build

Runs `vofusion` of both builds (this one, --build, against --baseline) on:
- both shared sequences whole, and each half on its own (xyz 0-149 / 150-299, rpy 0-49 / 50-99; a half
  is a TUM folder of list files whose images link to the shared ones, never copies);
- the shake at the tests' size (`rgbd-simulate --scene room --trajectory shake --size 320x240 --frames 90`)
  on every seed;
- the loop scene (300 frames) on every seed, ATE without loop closure (the run's tracked path) and with it.
Each run uses the config given (default: [output] mesh = false, write_rawlog = false: only the path);
with --candidate, this build's runs read the candidate's sections after it (a later value of a key wins).
Prints a markdown table (ATE RMSE per input and build, the difference in mm, rpy's 50 ms RPE p95), the
verdict and whether every input is within +2 % (issue 31's rule for a cheaper stage), and writes it to
<work>/rules.md. Runs are deterministic: one run per input and build (but see --perturb).

--perturb N runs each shared sequence, half and shake seed N times per build, with `[motion] ransac_seed`
1..N (the odometry's RANSAC; 1 is the default run), and compares the means (the table shows each mean and
its range); the loop scene runs once (its 300 frames at 640x480 would multiply the run's time). A 50-frame
half moves by tenths of a millimetre under any change at all (2026-12-03-shake-fast-turns.md), more than the
+2 % a cheaper stage may cost there, and a shake seed by millimetres: the seeds show whether a difference is
more than that. Both builds must know the key (built from 2026-12-03 on). An input over the cheaper stage's
+2 % whose runs overlap the baseline's runs is marked so in the verdict's line (the verdict stays the rule's).
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "data", "tum")
HALVES = {"rgbd_dataset_freiburg1_xyz_first300": [(0, 150), (150, 300)],
          "rgbd_dataset_freiburg1_rpy_first100": [(0, 50), (50, 100)]}
DEFAULT_CONFIG = "[output]\nmesh = false\nwrite_rawlog = false\n"
SEED_KEY = re.compile(r"^\s*ransac_seed\s*=", re.MULTILINE)


def log(msg):
    print("[bench rules] " + msg, file=sys.stderr, flush=True)


def list_lines(path):
    with open(path) as f:
        lines = f.read().splitlines()
    return [l for l in lines if l.startswith("#") or not l.strip()], [l for l in lines if l.strip() and not l.startswith("#")]


def make_half(seq_dir, first, end, out):
    """A TUM folder holding colour frames [first, end) of seq_dir's rgb.txt and the depth images taken
    within their time span (+-20 ms: the lists need not be the same length), everything else linked."""
    os.makedirs(out)
    head, rgb = list_lines(os.path.join(seq_dir, "rgb.txt"))
    rgb = rgb[first:end]
    t0, t1 = float(rgb[0].split()[0]) - 0.02, float(rgb[-1].split()[0]) + 0.02
    dhead, depth = list_lines(os.path.join(seq_dir, "depth.txt"))
    depth = [l for l in depth if t0 <= float(l.split()[0]) <= t1]
    for name, h, rows in (("rgb.txt", head, rgb), ("depth.txt", dhead, depth)):
        with open(os.path.join(out, name), "w") as f:
            f.write("\n".join(h + rows) + "\n")
    for name in os.listdir(seq_dir):
        if name not in ("rgb.txt", "depth.txt"):
            os.symlink(os.path.join(seq_dir, name), os.path.join(out, name))
    return out


def simulate(build, out, args):
    cmd = [os.path.join(build, "bin", "rgbd-simulate"), "--out", out] + args
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        sys.exit("bench rules: %s failed: %s" % (" ".join(cmd), last_line(done.stderr)))
    return out


def last_line(text):
    lines = text.strip().splitlines()
    return lines[-1] if lines else "(no message)"


def inputs(build, work, seeds):
    """[(name, kind, path, summary key)] in the order of the table; kind: whole, half, shake, loop, loop_lc."""
    runs = []
    for seq, halves in HALVES.items():
        path = os.path.join(SHARED, seq)
        if not os.path.isdir(path):
            sys.exit("bench rules: shared sequence missing: " + path)
        short = seq.split("_")[3]  # xyz, rpy
        runs.append((short, "whole", path, "ate"))
        for first, end in halves:
            # The folder keeps the sequence's name: vofusion takes TUM's camera (fr1) from it.
            half = make_half(path, first, end, os.path.join(work, "inputs", "%s_%d-%d" % (seq, first, end - 1)))
            runs.append(("%s %d-%d" % (short, first, end - 1), "half", half, "ate"))
    for s in seeds:
        runs.append(("shake seed %d" % s, "shake", simulate(build, os.path.join(work, "inputs", "shake_s%d" % s),
                     ["--scene", "room", "--trajectory", "shake", "--size", "320x240", "--frames", "90", "--seed", str(s)]),
                     "ate"))
    for s in seeds:
        rawlog = simulate(build, os.path.join(work, "inputs", "loop_s%d.rawlog" % s), ["--scene", "loop", "--seed", str(s), "--overwrite"])
        runs.append(("loop seed %d" % s, "loop", rawlog, "ate_tracked"))
        runs.append(("loop seed %d, loop closure" % s, "loop_lc", rawlog, "ate"))
    return runs


def knows_seed(vofusion):
    """Whether this vofusion reads [motion] ransac_seed (its --dump-config lists it)."""
    done = subprocess.run([vofusion, "--dump-config"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    return done.returncode == 0 and SEED_KEY.search(done.stdout) is not None


def seeded_config(config, seed, work, tag):
    """The build's config with RANSAC's seed set (read last: a later value of a key wins)."""
    path = os.path.join(work, "%s_ransac_seed%d.ini" % (tag, seed))
    if not os.path.exists(path):
        with open(config) as f:
            text = f.read()
        with open(path, "w") as f:
            f.write(text + "\n[motion]\nransac_seed = %d\n" % seed)
    return path


def run(vofusion, path, out, config):
    """summary.json of one run (kept in `out` for a second key of the same run: the loop scene's)."""
    summary = os.path.join(out, "summary.json")
    if not os.path.exists(summary):
        cmd = [vofusion, path, "--out", out, "--config", config]
        done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0:
            sys.exit("bench rules: %s failed: %s" % (" ".join(cmd), last_line(done.stderr)))
    with open(summary) as f:
        return json.load(f)


def read_ini(path, what):
    try:
        with open(path) as f:
            return f.read()
    except OSError as e:
        sys.exit("bench rules: %s: cannot read the %s INI (%s)" % (path, what, e.strerror))


def mm(a, b):
    return (b - a) * 1000.0


def seed_of(row):
    m = re.search(r"seed (\d+)", row["name"])
    return int(m.group(1)) if m else None


def verdict(rows, seeds):
    """The guide's rule, from the table: it carries over when every half is better by more than 1 mm, and
    every synthetic row's mean over seeds 1-5 is better by more than 1 mm with no seed of them worse by
    more than 1 mm (one seed's win does not carry the others); fewer than five seeds are no verdict."""
    halves = [r for r in rows if r["kind"] == "half"]
    half_wins = all(mm(r["base"], r["this"]) < -1.0 for r in halves)
    lines = ["- every half of both shared sequences better by > 1 mm: %s (%s)" % (
        "yes" if half_wins else "no", ", ".join("%s %+.2f" % (r["name"], mm(r["base"], r["this"])) for r in halves))]
    synthetic_wins = True
    for kind, label in (("shake", "shake"), ("loop", "loop scene without loop closure"), ("loop_lc", "loop scene with loop closure")):
        sel = [r for r in rows if r["kind"] == kind and seed_of(r) in range(1, 6)]  # the rule's seeds, not extra ones
        if not sel:
            synthetic_wins = False
            continue
        diff = sum(mm(r["base"], r["this"]) for r in sel) / len(sel)
        worse = sum(1 for r in sel if mm(r["base"], r["this"]) > 1.0)
        wins = diff < -1.0 and worse == 0
        synthetic_wins = synthetic_wins and wins
        lines.append("- %s, mean over seeds 1-5 (%d): %+.2f mm, %d seeds worse by > 1 mm; better by > 1 mm with none "
                     "worse: %s" % (label, len(sel), diff, worse, "yes" if wins else "no"))
    # Issue 31's rule for a stage made cheaper: accuracy within +2 % on every input (not a mean over inputs;
    # with --perturb, a shared input's or shake seed's figure is the mean of its runs). An input whose runs
    # under --perturb overlap the baseline's is marked: the RANSAC seed alone moves it that far, so a change
    # of rounding can too (2026-12-07-seventeenth-session.md). The verdict is the rule's, unchanged.
    def overlapping(r):
        this_runs, base_runs = r.get("this_runs", []), r.get("base_runs", [])
        return len(this_runs) > 1 and len(base_runs) > 1 and min(this_runs) <= max(base_runs)
    over = ["%s %+.1f %%%s" % (r["name"], 100.0 * (r["this"] / r["base"] - 1.0), " (the runs' ranges overlap)" if overlapping(r) else "")
            for r in rows if r["this"] > 1.02 * r["base"]]
    lines.append("- a cheaper stage's rule, every input within +2 %%: %s" % ("yes" if not over else "no (" + ", ".join(over) + ")"))
    if not set(range(1, 6)) <= set(seeds):
        lines.append("- **no verdict**: seeds %s; the rule counts seeds 1-5, never fewer" % ",".join(map(str, seeds)))
    else:
        lines.append("- **%s**" % ("carries over: the default may change" if half_wins and synthetic_wins
                                   else "does not carry over: the default stays"))
    return lines


def markdown(rows, rpe, seeds, this_name, base_name, command):
    out = ["# Does it carry over? %s against %s" % (this_name, base_name), "",
           "`%s`, %s. ATE RMSE [m]; difference in mm (negative: this build better)." % (command, time.strftime("%Y-%m-%d %H:%M")), "",
           "Compare figures only within one run: the same build gives other synthetic figures on another machine "
           "(bench/results/2026-11-29-first-frame.md).", "",
           "| input | baseline | this build | difference, mm |", "|---|---:|---:|---:|"]
    def cell(r, tag):
        runs = r.get(tag + "_runs", [])
        if len(runs) < 2:
            return "%.5f" % r[tag]
        return "%.5f (%.5f-%.5f)" % (r[tag], min(runs), max(runs))
    perturbed = [r for r in rows if len(r.get("this_runs", [])) > 1]
    if perturbed:
        out.insert(-2, "Shared sequences, halves and shake seeds: the mean of %d runs with `[motion] ransac_seed` 1-%d (their range in "
                       "brackets); the difference is of the means." % (len(perturbed[0]["this_runs"]), len(perturbed[0]["this_runs"])))
        out.insert(-2, "")
    for r in rows:
        out.append("| %s | %s | %s | %+.2f |" % (r["name"], cell(r, "base"), cell(r, "this"), mm(r["base"], r["this"])))
    out += ["", "rpy_first100's 50 ms translation RPE, 95th percentile [m]%s: baseline %.4f, this build %.4f." % (
        (" (the runs' mean)" if perturbed else "",) + rpe)]
    out += ["", "Verdict (a default changes only if it wins by > 1 mm on each half and on the synthetic seeds):", ""]
    out += verdict(rows, seeds)
    return "\n".join(out) + "\n"


def main(argv):
    ap = argparse.ArgumentParser(prog="bench/run --rules", allow_abbrev=False)
    ap.add_argument("--rules", action="store_true")
    ap.add_argument("--baseline", required=True, help="the other build's directory (holding bin/vofusion)")
    ap.add_argument("--build", default=os.environ.get("VOFUSION_BUILD", os.path.join(ROOT, "build")))
    ap.add_argument("--config", default=None, help="INI given to every run of both builds")
    ap.add_argument("--candidate", default=None,
                    help="INI added after the config to this build's runs only, starting with a [section]: "
                         "a key's new value (with --baseline the same build)")
    ap.add_argument("--seeds", default="1,2,3,4,5")
    ap.add_argument("--perturb", type=int, default=1,
                    help="runs of each shared sequence, half and shake seed per build, [motion] ransac_seed 1..N; means compared")
    ap.add_argument("--work", default=None, help="inputs and run outputs (default <build>/bench-rules)")
    a = ap.parse_args(argv)
    try:
        seeds = sorted({int(s) for s in a.seeds.split(",")})
    except ValueError:
        sys.exit("bench rules: --seeds %s: give seed numbers separated by commas (1,2,3,4,5)" % a.seeds)
    work = a.work or os.path.join(a.build, "bench-rules")
    for path in (a.config, a.candidate):
        if path and os.path.realpath(path).startswith(os.path.realpath(work) + os.sep):
            sys.exit("bench rules: %s lies in the work folder %s, which is emptied first: keep it elsewhere" % (path, work))
    config_text = read_ini(a.config, "config") if a.config else DEFAULT_CONFIG
    candidate_text = read_ini(a.candidate, "candidate") if a.candidate else None
    first_line = next((l.strip() for l in (candidate_text or "").splitlines()
                       if l.strip() and not l.strip().startswith(("#", ";"))), "[")
    if not first_line.startswith("["):
        sys.exit("bench rules: %s: the candidate must start with a [section] (its keys would join the config's last one)"
                 % a.candidate)
    # Everything that can refuse the run, before the work folder (the last run's results) is emptied.
    builds = {"this": os.path.join(a.build, "bin", "vofusion"), "base": os.path.join(a.baseline, "bin", "vofusion")}
    for b in list(builds.values()) + [os.path.join(a.build, "bin", "rgbd-simulate")]:
        if not os.access(b, os.X_OK):
            sys.exit("bench rules: no executable " + b)
    if a.perturb < 1:
        sys.exit("bench rules: --perturb %d: give the number of runs per shared input and shake seed (1 = no perturbation)" % a.perturb)
    if a.perturb > 1:
        for path, text in ((a.config, config_text), (a.candidate, candidate_text or "")):
            if SEED_KEY.search(text):
                sys.exit("bench rules: %s sets ransac_seed, which --perturb sets for each run: drop one of the two" % path)
        for exe in builds.values():
            if not knows_seed(exe):
                sys.exit("bench rules: %s does not read [motion] ransac_seed (built before 2026-12-03): --perturb needs "
                         "both builds to know it" % exe)
    # Inputs and runs of this invocation only (builds change): emptied first, if this command made it.
    marker = os.path.join(work, ".bench-rules")
    if os.path.exists(work) and os.listdir(work) and not os.path.exists(marker):
        sys.exit("bench rules: %s is not empty and not a bench rules folder: give --work another folder" % work)
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    open(marker, "w").close()
    configs = {"base": os.path.join(work, "config.ini")}
    with open(configs["base"], "w") as f:
        f.write(config_text)
    configs["this"] = configs["base"]
    if candidate_text is not None:
        # This build's runs read the common config, then the candidate's sections (a later value wins).
        configs["this"] = os.path.join(work, "candidate.ini")
        with open(configs["this"], "w") as f:
            f.write(config_text + "\n" + candidate_text + "\n")
    runs = inputs(a.build, work, seeds)
    rows, rpe = [], None
    start = time.time()
    for i, (name, kind, path, key) in enumerate(runs):
        row = {"name": name, "kind": kind}
        for tag, exe in builds.items():
            base_out = os.path.join(work, tag, name.split(",")[0].replace(" ", "_"))
            perturbed = a.perturb > 1 and kind in ("whole", "half", "shake")
            ates, rpes = [], []
            for seed in range(1, a.perturb + 1) if perturbed else [None]:
                out = base_out if seed is None else "%s_ransac_seed%d" % (base_out, seed)
                config = configs[tag] if seed is None else seeded_config(configs[tag], seed, work, tag)
                s = run(exe, path, out, config)
                try:
                    ates.append(s[key]["rmse"])
                    if name == "rpy":
                        rpes.append(s["rpe_50ms"]["trans_m"]["p95"])
                except KeyError as e:
                    sys.exit("bench rules: %s/summary.json has no %s (ground truth missing, or loop closure off in the config?)"
                             % (out, e))
            row[tag] = sum(ates) / len(ates)
            row[tag + "_runs"] = ates
            if rpes:
                row["rpe_" + tag] = sum(rpes) / len(rpes)
        if name == "rpy":
            rpe = (row["rpe_base"], row["rpe_this"])
        rows.append(row)
        elapsed = time.time() - start
        log("%d/%d %s: %.5f -> %.5f  (%.0f s, ETA %.0f s)" % (i + 1, len(runs), name, row["base"], row["this"], elapsed,
                                                            elapsed / (i + 1) * (len(runs) - i - 1)))
    this_name = a.build if candidate_text is None else "%s with the candidate %s" % (a.build, a.candidate)
    text = markdown(rows, rpe, seeds, this_name, a.baseline, "bench/run " + " ".join(argv))
    if candidate_text is not None:
        text += "\nThe candidate (`%s`), read after the config by this build's runs only:\n\n```ini\n%s\n```\n" % (
            a.candidate, candidate_text.strip())
    with open(os.path.join(work, "rules.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
