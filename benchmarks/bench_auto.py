"""Sweeps with automatic contact (MODEL.md section 5) on the shipped T-bone case: time per point. Not a test.

    .venv/bin/python benchmarks/bench_auto.py [--points N] [--repeats R] [--label TEXT]

Two grids of about N points over ``ks_jax/cases/auto_tbone.json``: the pickup's speed (20-40 mph) against
the sedan's lateral position (-5..5 ft: neither vehicle turns, the first contact has a closed form), and
against the sedan's yaw rate (-60..60 deg/s: the first contact is searched). Run it in alternating
processes with an older checkout on ``PYTHONPATH`` (from outside the repository) to compare versions.
Prints the first call (compile + run) and the median time per point of the calls after it.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from importlib import resources

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import ks_jax  # noqa: E402
from ks_jax import units as U  # noqa: E402

GRIDS = {
    "lateral position (no turning)": ("vehicles[0].position[1]", -5 * U.FT, 5 * U.FT),
    "yaw rate (a vehicle turns)": ("vehicles[0].yaw_rate", math.radians(-60), math.radians(60)),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1 << 18)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--label", default="this checkout")
    args = ap.parse_args()
    with resources.as_file(resources.files("ks_jax.cases") / "auto_tbone.json") as path:
        case = ks_jax.load_case(path)
    side = int(round(math.sqrt(args.points)))
    speeds = np.linspace(20, 40, side) * U.MPH
    print(f"{args.label}: {ks_jax.__file__}, {side}x{side} points, jax {jax.__version__}, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    for name, (path, lo, hi) in GRIDS.items():
        over = {"vehicles[1].speed": speeds, path: np.linspace(lo, hi, side)}
        t = time.perf_counter()
        res = ks_jax.sweep(case, over=over, progress=False)
        first = time.perf_counter() - t
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            ks_jax.sweep(case, over=over, progress=False)
            times.append(time.perf_counter() - t)
        print(f"  {name:<32} first call {first:6.2f} s, then {statistics.median(times) / side**2 * 1e6:7.2f} us per "
              f"point (median of {args.repeats}); {res.status_counts}")


if __name__ == "__main__":
    main()
