"""Memory of ``jax.jit(jax.vmap(ks_jax.exchange))`` over one batch: the chunked program (``exchange``'s
vmap rule) against the whole-batch program (``exchange_with_status`` after ``input_status``). Not a test.

    .venv/bin/python benchmarks/bench_vmap_memory.py [--rows 1048576]

For each program, in a fresh process: XLA's temporary and output bytes (``compiled.memory_analysis()``)
and how much one call raised the process's peak resident memory (ru_maxrss).
"""

import argparse
import datetime
import resource
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_kernel import random_batch  # noqa: E402

from ks_jax.exchange import exchange, exchange_with_status, input_status  # noqa: E402

MIB = 2.0**20


def measure(variant, n):
    _, last = random_batch(n)
    first = jax.tree_util.tree_map(lambda x: jnp.moveaxis(x, -1, 0), last)
    del last
    fn = exchange if variant == "chunked" else (lambda *a: exchange_with_status(*a, 0.0, input_status(*a)))
    jitted = jax.jit(jax.vmap(fn))
    mem = jitted.lower(*first).compile().memory_analysis()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    jax.block_until_ready(jitted(*first))
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"{variant:8} XLA temporaries {mem.temp_size_in_bytes / MIB:7.1f} MiB, results "
          f"{mem.output_size_in_bytes / MIB:7.1f} MiB; peak RSS {before / 1024:7.0f} -> {after / 1024:7.0f} MiB "
          f"(+{(after - before) / 1024:.0f})", flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--variant", choices=["chunked", "whole"], help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.variant:
        measure(args.variant, args.rows)
        return
    print(f"jax.jit(jax.vmap(exchange)) memory, {args.rows} rows, batch-first, float64; "
          f"{datetime.datetime.now().astimezone().isoformat(timespec='seconds')}; jax {jax.__version__}")
    for variant in ("chunked", "whole"):  # each in its own process: ru_maxrss is a high-water mark
        subprocess.run([sys.executable, __file__, "--rows", str(args.rows), "--variant", variant], check=True)


if __name__ == "__main__":
    main()
