"""The machine a benchmark ran on, for its results' header: figures from another machine do not compare."""
import os


def describe():
    """'<CPU model>, <n> cores, AVX2 <yes|no>, AVX-512 <yes|no>' from /proc/cpuinfo."""
    model, flags = "unknown CPU", set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and model == "unknown CPU":
                    model = value.strip()
                elif key.strip() == "flags" and not flags:
                    flags = set(value.split())
    except OSError:
        pass
    yes = lambda flag: "yes" if flag in flags else "no"
    return "%s, %d cores, AVX2 %s, AVX-512 %s" % (model, os.cpu_count() or 0, yes("avx2"), yes("avx512f"))
