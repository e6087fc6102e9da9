"""Side-by-side A/B of gradient / forward through ``jax.vmap(exchange)``, for variants of the library
selected by module attributes read when a function is traced. Not a test.

    .venv/bin/python benchmarks/ab_gradient.py [--rows N] [--repeats R] [--loss delta-V|residuals|both] \
        [--whole | --summed] MODULE.ATTR=VALUE [MODULE.ATTR=VALUE ...]

Each argument is one variant: the attribute is set, then ``jax.value_and_grad`` of bench_kernel.py's
batched loss (batch-first) is traced and compiled; ``--whole``: through ``exchange_with_status``, one
whole-batch program, instead of ``exchange``. The forward (``jax.jit`` of the loss, traced with the
attributes as they were at start) and every variant are then timed in rounds, one call each per round;
the script prints the median time per row and the median over rounds of gradient / forward, and the
largest relative difference of each variant's gradient from the first's. ``--summed`` adds, per loss,
the gradient of the same loss built by ``ks_jax.sum_over_rows`` (divided by the same forward: the
built loss's forward is the same computation through ``jax.vmap(exchange)``). For variants that exist
only as a patch (benchmarks/RESULTS.md says which), apply the patch first.
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_kernel as bk  # noqa: E402


def _attribute(spec):
    """(module, attribute name, value) of MODULE.ATTR=VALUE."""
    target, value = spec.split("=", 1)
    module, attr = target.rsplit(".", 1)
    return importlib.import_module(module), attr, value


def set_attribute(spec):
    module, attr, value = _attribute(spec)
    setattr(module, attr, eval(value, {}))  # noqa: S307 (a benchmark's command line)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--loss", choices=("delta-V", "residuals", "both"), default="both")
    ap.add_argument("--whole", action="store_true", help="the whole-batch program (exchange_with_status)")
    ap.add_argument("--summed", action="store_true",
                    help="also the gradient of the same loss built by ks_jax.sum_over_rows (after the variants)")
    ap.add_argument("variants", nargs="+", metavar="MODULE.ATTR=VALUE")
    args = ap.parse_args()
    if args.summed and args.whole:
        ap.error("--summed compares with the path through jax.vmap(exchange); leave out --whole")
    n = args.rows
    _, last = bk.random_batch(n)
    first = bk.batch_first(last)
    losses = {"delta-V": bk.delta_v, "residuals": bk.residuals}
    names = list(losses) if args.loss == "both" else [args.loss]
    status = jax.vmap(bk.input_status)(*first) if args.whole else None
    path = "whole-batch exchange_with_status" if args.whole else "jax.vmap(exchange)"
    print(f"{path}, {n} rows, jax {jax.__version__}, {jax.devices()[0].device_kind}; {args.repeats} rounds")
    calls = {}
    originals = {}  # the attributes as they were: each loss's forward is traced with them
    for spec in args.variants:
        module, attr, _ = _attribute(spec)
        originals.setdefault((module, attr), getattr(module, attr))
    for name in names:
        for (module, attr), value in originals.items():
            setattr(module, attr, value)
        loss = bk.batched_loss(losses[name], 0, chunked=not args.whole)
        fwd = jax.jit(lambda a, loss=loss: loss(a, status))
        jax.block_until_ready(fwd(first))
        calls[(name, "forward")] = fwd
        reference = None
        for spec in args.variants:
            set_attribute(spec)
            grad = jax.jit(jax.value_and_grad(lambda a, loss=loss: loss(a, status)))
            start = time.perf_counter()
            _, g = jax.block_until_ready(grad(first))
            compiled = time.perf_counter() - start
            leaves = jax.tree_util.tree_leaves(g)
            reference = leaves if reference is None else reference
            diff = max(float(jnp.max(jnp.abs(a - b) / (1 + jnp.abs(b)))) for a, b in zip(leaves, reference))
            finite = all(bool(jnp.all(jnp.isfinite(x))) for x in leaves)
            print(f"{name:9s} {spec}: first call {compiled:.1f} s, largest relative difference from the first "
                  f"variant {diff:.1e}, finite {finite}", flush=True)
            calls[(name, spec)] = grad
        if args.summed:  # the same loss, its gradient each chunk's value and gradient in one program
            summed = bk.batched_loss(losses[name], 0, summed=True)
            grad = jax.jit(jax.value_and_grad(lambda a, summed=summed: summed(a, None)))
            start = time.perf_counter()
            _, g = jax.block_until_ready(grad(first))
            compiled = time.perf_counter() - start
            diff = max(float(jnp.max(jnp.abs(a - b) / (1 + jnp.abs(b))))
                       for a, b in zip(jax.tree_util.tree_leaves(g), reference))
            print(f"{name:9s} sum_over_rows: first call {compiled:.1f} s, largest relative difference from the "
                  f"first variant {diff:.1e}", flush=True)
            calls[(name, "sum_over_rows")] = grad
    times = {k: [] for k in calls}
    for _ in range(args.repeats):
        for k, fn in calls.items():
            start = time.perf_counter()
            jax.block_until_ready(fn(first))
            times[k].append(time.perf_counter() - start)
    for (name, spec), t in times.items():
        base = times[(name, "forward")]
        print(f"{name:9s} {spec:40s} {statistics.median(t) * 1e9 / n:7.0f} ns/row   / forward "
              f"{statistics.median(b / a for a, b in zip(base, t)):.2f}")


if __name__ == "__main__":
    main()
