"""Peak memory of a 10^8-point sweep (10000 x 10000 grid, one output). Not a test.

    .venv/bin/python benchmarks/bench_sweep_memory.py [--keep float32|none] [--n 10000]

--keep float32: the output is stored as float32 (0.4 GB for 10^8 points) plus the int8 status;
--keep none: nothing is stored; a per-chunk callback reduces the output (its maximum) as it goes.
Prints the time and the peak resident memory of the process (VmHWM; ``peak_rss_mib``).
"""

import argparse
import datetime
import resource
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import ks_jax

CASE = Path(ks_jax.__file__).parent / "cases" / "seed_000_saturn_pontiac.json"


def peak_rss_mib():
    """The process's peak resident memory in MiB: VmHWM of /proc/self/status on Linux, which starts
    afresh at exec. (``ru_maxrss`` keeps the high-water mark of the process this one was started
    from, up to its exec: run from a large process, such as bench_kernel.py, it reports that one's.)"""
    try:
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux, bytes on macOS


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--keep", choices=["float32", "none"], default="float32")
    ap.add_argument("--n", type=int, default=10000, help="grid side (points = n^2)")
    args = ap.parse_args()
    case = ks_jax.load_case(CASE)
    over = {"vehicles[1].speed": np.linspace(5, 30, args.n), "contact.restitution": np.linspace(0, 0.5, args.n)}
    out = "vehicles[0].delta_v_magnitude"
    peak = {"max": -np.inf}

    def reduce(lo, hi, chunk):
        peak["max"] = max(peak["max"], float(np.nanmax(chunk[out])))

    t = time.perf_counter()
    if args.keep == "float32":
        r = ks_jax.sweep(case, over=over, outputs=[out], output_dtype=np.float32, progress=False)
        summary = f"max delta-V {np.nanmax(r[out]):.4f} m/s, status {r.status_counts}"
    else:
        r = ks_jax.sweep(case, over=over, outputs=[out], on_chunk=reduce, keep=False, progress=False)
        summary = f"max delta-V {peak['max']:.4f} m/s, status {r.status_counts}"
    dt = time.perf_counter() - t
    rss = peak_rss_mib()
    print(f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, jax {jax.__version__}, "
          f"{args.n ** 2:.3g} points, keep={args.keep}: {dt:.1f} s (incl. compile), peak RSS {rss:.0f} MiB; {summary}")


if __name__ == "__main__":
    main()
