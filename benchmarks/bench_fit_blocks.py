"""Benchmark: the fit's solver called in blocks of rows (``fit.reconstruction.ROWS_PER_CALL``).

    python benchmarks/bench_fit_blocks.py [--n 1000] [--starts 8] [--repeats 3] [SIZE ...]

bench_fit.py's random sliding cases (n cases x starts rows), fitted by ``fit.reconstruction._run`` in calls of
SIZE rows each (default sizes: 128 256 500 512 1000 8000 8192), the last call padded. Rounds of one timed call
per size, after one untimed call per size (the compile). Prints the seconds of each round and the sum over
calls of rows x the most iterations in the call (what the loop computes: a call runs until its slowest row has
converged). A size of n x starts is one call of every row, as a fit without refits makes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_fit as bf  # noqa: E402
from fit import reconstruction as rc  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--starts", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("sizes", type=int, nargs="*", default=[128, 256, 500, 512, 1000, 8000, 8192])
    a = ap.parse_args(argv)
    cases, _, evidence, unknowns, _ = bf.sliding_cases(a.n, 0)
    prepared = [rc._prepare(c, u, e) for c, u, e in zip(cases, unknowns, evidence)]
    problem = prepared[0][2]
    arrays = [rc._arrays(c, u, e, jnp.float64) for c, (u, e, _) in zip(cases, prepared)]
    rng = np.random.default_rng(1)
    x0 = np.stack([rc._first_starts(u, arr, a.starts, rng) for (u, _, _), arr in zip(prepared, arrays)])
    z0 = np.stack([rc.to_z(x, arr["lo"], arr["hi"]) for x, arr in zip(x0, arrays)])
    st = {k: np.stack([arr[k] for arr in arrays]) for k in ("values", "sigmas", "lo", "hi", "pm", "pw")}
    inputs = rc._stack([arr["inputs"] for arr in arrays])
    args = (problem, "lm", 50, inputs, st["values"], st["sigmas"], st["lo"], st["hi"], st["pm"], st["pw"], z0,
            bf.SMOOTHING, jnp.float64, a.starts)
    print(f"{jax.devices()[0].device_kind}, {a.n} cases x {a.starts} starts, {' '.join(sys.argv)}")
    for size in a.sizes:
        rc._run(*args, block=size)
    times = {size: [] for size in a.sizes}
    for _ in range(a.repeats):
        for size in a.sizes:
            t = time.perf_counter()
            out = rc._run(*args, block=size)
            times[size].append(time.perf_counter() - t)
    it = out["iterations"].reshape(-1)
    for size in a.sizes:
        work = sum(int(it[i:i + size].max()) * size for i in range(0, len(it), size))
        print(f"{size:6d} rows per call: {' '.join(f'{t:.2f}' for t in times[size])} s; rows x iterations {work}")


if __name__ == "__main__":
    main()
