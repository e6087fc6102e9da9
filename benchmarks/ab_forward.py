"""The forward of the library as it is checked out, in rounds beside NumPy: ``jax.jit(jax.vmap(exchange))``
(batch-first), ``exchange_batch`` and the NumPy reference. Not a test.

    .venv/bin/python benchmarks/ab_forward.py [--rows N] [--repeats R] [--label TEXT] [--save FILE.npz]

For a variant that exists only as a patch (benchmarks/RESULTS.md says which), run it on main and with the
patch applied, in alternating processes, and compare the lines. ``--save`` keeps the results of
``jit(vmap)`` to compare the two versions' values. Prints the median time per row of each, its median
page faults per call and the median over rounds of NumPy's time / its time.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_kernel as bk  # noqa: E402
import numpy_ks  # noqa: E402

import ks_jax  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--label", default="this checkout")
    ap.add_argument("--save", metavar="FILE.npz")
    args = ap.parse_args()
    n = args.rows
    nps, last = bk.random_batch(n)
    first = bk.batch_first(last)
    vmapped = jax.jit(jax.vmap(ks_jax.exchange))
    out = jax.block_until_ready(vmapped(*first))
    if args.save:
        np.savez(args.save, *[np.asarray(x) for x in jax.tree_util.tree_leaves(out)])
    fns = {"jit(vmap)": lambda: jax.block_until_ready(vmapped(*first)),
           "exchange_batch": lambda: ks_jax.exchange_batch(*first),
           "numpy": lambda: numpy_ks.exchange(*nps)}
    for fn in fns.values():
        fn()
    usage, times = {}, {k: [] for k in fns}
    for _ in range(args.repeats):
        for k, t in bk.rounds(fns, 1, usage).items():
            times[k] += t
    print(args.label, " ".join(
        f"{k} {statistics.median(times[k]) * 1e9 / n:5.0f} ns/row (faults {statistics.median(u[1] for u in usage[k]):6.0f}, "
        f"numpy/this {bk.ratio(times, k, 'numpy'):5.2f})" for k in fns))


if __name__ == "__main__":
    main()
