"""Rows per chunk, side by side: the forward at several chunk sizes in rounds beside NumPy. Not a test.

    .venv/bin/python benchmarks/ab_chunk.py [--rows N] [--repeats R] [--sizes 4096,8192,16384,32768]

Each size is timed two ways: ``exchange_batch(..., chunk=size)`` and ``jax.jit(jax.vmap(exchange))``
traced with ``ks_jax.exchange.CHUNK_ROWS = size`` (its vmap rule reads it when it is traced). Every
variant runs once per round, after NumPy; the script prints the median time per row of each and the
median over rounds of NumPy's time / its time. The chunk size (16384 rows) was chosen on machines with a
32 MiB last-level cache; run this on a new kind of machine before changing it.
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_kernel as bk  # noqa: E402
import numpy_ks  # noqa: E402

import ks_jax  # noqa: E402

ex = importlib.import_module("ks_jax.exchange")  # the module (ks_jax.exchange is the function)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--sizes", default="4096,8192,16384,32768", help="rows per chunk, comma-separated")
    args = ap.parse_args()
    n, sizes = args.rows, [int(s) for s in args.sizes.split(",")]
    print(f"{bk.cpu_model()}, jax {jax.__version__}, {n} rows, {args.repeats} rounds")
    nps, last = bk.random_batch(n)
    first = bk.batch_first(last)
    fns = {"NumPy": lambda: numpy_ks.exchange(*nps)}
    for size in sizes:
        fns[f"exchange_batch, chunk {size}"] = lambda size=size: ks_jax.exchange_batch(*first, chunk=size)
    default = ex.CHUNK_ROWS
    for size in sizes:
        ex.CHUNK_ROWS = size
        fn = jax.jit(jax.vmap(ks_jax.exchange))
        jax.block_until_ready(fn(*first))  # traced (and compiled) at this size
        fns[f"jit(vmap), chunk {size}"] = lambda fn=fn: jax.block_until_ready(fn(*first))
    ex.CHUNK_ROWS = default
    for fn in fns.values():  # warm
        fn()
    times = {k: [] for k in fns}
    for _ in range(args.repeats):
        for k, fn in fns.items():
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    for k, ts in times.items():
        ratios = [a / b for a, b in zip(times["NumPy"], ts)]
        print(f"{k:30s} {statistics.median(ts) / n * 1e9:8.1f} ns/row   NumPy / this {statistics.median(ratios):6.2f}"
              f"   rounds {' '.join(f'{r:.1f}' for r in ratios)}")


if __name__ == "__main__":
    main()
