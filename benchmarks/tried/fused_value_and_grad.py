"""A per-chunk value and gradient for losses that are sums over rows, tried and not kept. Not a test.

    .venv/bin/python benchmarks/tried/fused_value_and_grad.py [--rows N] [--repeats R] [SIZE ...]

For a loss that is a sum over rows of a row's loss, each chunk's share of the gradient depends only on
that chunk's rows, so a chunk's forward and reverse pass can run back to back (``jax.lax.map`` of
``jax.value_and_grad`` over chunks of SIZE rows) with no second forward pass and no batch-sized
residuals. This script times that, for bench_kernel.py's two losses (batch-first), against the
chunked forward and gradient of main (``jax.value_and_grad`` of the loss through ``jax.vmap(exchange)``),
in rounds of one call each, and prints ns per row and the median of time / forward. N must be a
multiple of each SIZE.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import bench_kernel as bk  # noqa: E402

from ks_jax.exchange import exchange  # noqa: E402


def per_chunk(row_loss, n, size):
    """value_and_grad of the summed loss, chunk by chunk (each chunk inside vmap's whole-batch rule)."""
    def chunk_loss(rows):
        r = jax.vmap(exchange)(*rows)
        return jnp.sum(jnp.where(r.contact.status == 0, row_loss(r), 0.0))

    def f(args):
        chunks = jax.tree_util.tree_map(lambda x: x.reshape((n // size, size) + x.shape[1:]), args)
        values, grads = jax.lax.map(jax.value_and_grad(chunk_loss), chunks)
        return values.sum(), jax.tree_util.tree_map(lambda x: x.reshape((n,) + x.shape[2:]), grads)

    return jax.jit(f)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("sizes", type=int, nargs="*", default=[1024, 4096, 16384])
    args = ap.parse_args()
    n = args.rows
    _, last = bk.random_batch(n)
    first = bk.batch_first(last)
    print(f"{n} rows, jax {jax.__version__}, {jax.devices()[0].device_kind}; {args.repeats} rounds")
    calls = {}
    for name, row_loss in (("residuals", bk.residuals), ("delta-V", bk.delta_v)):
        loss = bk.batched_loss(row_loss, 0, chunked=True)
        calls[(name, "forward")] = jax.jit(lambda a, loss=loss: loss(a, None))
        calls[(name, "gradient (main)")] = jax.jit(jax.value_and_grad(lambda a, loss=loss: loss(a, None)))
        for size in args.sizes:
            calls[(name, f"per chunk of {size}")] = per_chunk(row_loss, n, size)
        reference = None
        for key, fn in calls.items():
            if key[0] != name or key[1] == "forward":
                continue
            leaves = jax.tree_util.tree_leaves(jax.block_until_ready(fn(first))[1])
            reference = reference or leaves
            diff = max(float(jnp.max(jnp.abs(a - b) / (1 + jnp.abs(b)))) for a, b in zip(leaves, reference))
            print(f"{name:9s} {key[1]:20s} largest relative difference from main {diff:.1e}", flush=True)
        jax.block_until_ready(calls[(name, "forward")](first))
    times = bk.rounds({k: (lambda fn=fn: jax.block_until_ready(fn(first))) for k, fn in calls.items()}, args.repeats)
    for (name, label), t in times.items():
        print(f"{name:9s} {label:20s} {statistics.median(t) * 1e9 / n:7.0f} ns/row   / forward "
              f"{bk.ratio(times, (name, 'forward'), (name, label)):.2f}")

if __name__ == "__main__":
    main()
