"""Where a benchmark writes its tables: the committed bench/results for its full run, and beside its runs
(<build>/bench-runs/results) for any other, which must not replace the committed tables."""
import os

COMMITTED = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def results_dir(full_run, build):
    return COMMITTED if full_run else os.path.join(build, "bench-runs", "results")
