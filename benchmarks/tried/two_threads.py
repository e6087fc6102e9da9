"""``exchange_batch``'s three stages from two Python threads at once (tried; the library is unchanged).

    .venv/bin/python benchmarks/tried/two_threads.py [--rows 1048576] [--repeats 5] [--sizes 2048,4096,8192,16384]

XLA's CPU backend splits the work between its threads loop by loop, as its cost model decides for each
fused loop (one core alone ran the stage path at 557 ns per row, both at 382: an earlier entry of
benchmarks/RESULTS.md). Smaller chunks give it less to split; computed two at a time by two Python threads
(each thread every other chunk), they might keep both cores busy with less waiting. This script times the
stages (``ks_jax.batch._stages``: the calls of ``exchange_batch`` without the copy into NumPy arrays) over
the same batch, for each chunk size, from one thread and from two, in interleaved rounds, and prints the
median and the fastest time per row of each.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import bench_kernel as bk  # noqa: E402

from ks_jax import batch as kb  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--sizes", default="2048,4096,8192,16384", help="rows per chunk, comma-separated")
    args = ap.parse_args()
    n = args.rows
    _, last = bk.random_batch(n)
    batch = tuple(bk.batch_first(last))  # JAX arrays, batch first
    pool = ThreadPoolExecutor(2)

    def variant(size, threads):
        prep, imp, res = kb._stages(size, 0.0)
        starts = [min(lo, n - size) for lo in range(0, n, size)]

        def run(part):
            result = None
            for start in part:
                rows, prepared = prep(batch, start)
                result = res(rows, prepared, imp(rows, prepared))
            jax.block_until_ready(result)

        if threads == 1:
            return lambda: run(starts)
        return lambda: list(pool.map(run, [starts[0::2], starts[1::2]]))

    fns = {(size, t): variant(size, t) for size in map(int, args.sizes.split(",")) for t in (1, 2)}
    bk.rounds(fns, 2)  # compiled and warm
    times = bk.rounds(fns, args.repeats)
    print(f"{bk.cpu_model()}, jax {jax.__version__}, {n} rows, {args.repeats} rounds")
    for (size, threads), ts in times.items():
        print(f"chunk {size:6d}, {threads} thread(s): {statistics.median(ts) / n * 1e9:7.1f} ns/row"
              f" (fastest round {min(ts) / n * 1e9:.1f})")


if __name__ == "__main__":
    main()
