"""A sweep sharded over several devices against the same sweep on one of them. Not a test.

    JAX_NUM_CPU_DEVICES=2 .venv/bin/python benchmarks/bench_sweep_sharded.py [--n 1000]

Runs an n x n grid (default outputs) with ``ks_jax.sweep`` over all of ``jax.devices()`` (every
chunk split along its rows over a 1-D mesh) and over the first device alone, each twice (the
first call compiles), and prints both times and the largest difference between the two results.
On a CPU the host devices (JAX_NUM_CPU_DEVICES, or XLA_FLAGS=--xla_force_host_platform_device_count)
share the machine's cores, so the figure shows that the sharded
program runs and what splitting a chunk costs or gains there; on several GPUs the same call
spreads the work over them. Without the flag there is one device and the two runs are the same.
"""

import argparse
import datetime
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import ks_jax

CASE = Path(ks_jax.__file__).parent / "cases" / "seed_000_saturn_pontiac.json"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000, help="grid side (points = n^2)")
    args = ap.parse_args()
    case = ks_jax.load_case(CASE)
    over = {"vehicles[1].speed": np.linspace(2, 30, args.n), "contact.friction": np.linspace(0, 1, args.n)}
    runs = {}
    for name, devices in (("all devices", jax.devices()), ("one device", jax.devices()[:1])):
        t = time.perf_counter()
        ks_jax.sweep(case, over, progress=False, devices=devices)
        first = time.perf_counter() - t
        runs[name] = (first, ks_jax.sweep(case, over, progress=False, devices=devices))
    (f_all, r_all), (f_one, r_one) = runs["all devices"], runs["one device"]
    diff = max(float(np.nanmax(np.abs(np.asarray(r_all[p], float) - np.asarray(r_one[p], float))))
               for p in r_all.output_paths)
    same_nan = all(np.array_equal(np.isnan(np.asarray(r_all[p], float)), np.isnan(np.asarray(r_one[p], float)))
                   for p in r_all.output_paths)
    print(f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, jax {jax.__version__}, "
          f"{r_all.points:.3g} points: {len(jax.devices())} {jax.devices()[0].platform} device(s) "
          f"{r_all.seconds:.2f} s, one device {r_one.seconds:.2f} s (first calls incl. compile {f_all:.2f}, "
          f"{f_one:.2f} s); largest difference {diff:.1e}, NaN in the same places: {same_nan}; "
          f"status {r_all.status_counts}")


if __name__ == "__main__":
    main()
