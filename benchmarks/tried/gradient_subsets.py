"""Gradient / forward when the batched loss is differentiated with respect to some inputs only (a
measurement; the library is unchanged).

    .venv/bin/python benchmarks/tried/gradient_subsets.py [--rows 1048576] [--repeats 5] [--summed]

bench_kernel.py differentiates its two losses with respect to every input of every row, masses,
inertias and box dimensions included. A reconstruction fits a few inputs per collision (speeds,
headings, yaw rates, the impulse centroid, the normal, restitution, friction): the derivatives of the
rest are never needed, and JAX leaves them out of the reverse pass. This script times, in the same
rounds, the forward of each loss through ``jax.vmap(exchange)`` (batch-first) and
``jax.value_and_grad`` of it with respect to:
- every input (as bench_kernel.py);
- the two states and the contact (no vehicle data);
- the unknowns of a reconstruction: both velocities, yaws and angular velocities, the contact point,
  the normal, restitution and friction.
It prints the median time per row and the median over rounds of gradient / forward. ``--summed``: the
gradients of the same losses built by ``ks_jax.sum_over_rows`` (divided by the same forward, through
``jax.vmap(exchange)``: the built loss's forward is that computation).
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


def split(args, which):
    """(differentiated part, the rest) of the five input trees."""
    _, s1, _, s2, c = args
    if which == "all":
        return args, None
    if which == "states":
        return (s1, s2, c), args
    return (s1.velocity, s1.yaw, s1.angular_velocity, s2.velocity, s2.yaw, s2.angular_velocity,
            c.point, c.normal, c.restitution, c.friction), args


def merge(part, rest, which):
    """The five input trees from ``split``'s two parts."""
    if which == "all":
        return part
    v1, s1, v2, s2, c = rest
    if which == "states":
        s1, s2, c = part
        return v1, s1, v2, s2, c
    w1, yaw1, om1, w2, yaw2, om2, p, n, e, mu = part
    return (v1, s1._replace(velocity=w1, yaw=yaw1, angular_velocity=om1), v2,
            s2._replace(velocity=w2, yaw=yaw2, angular_velocity=om2),
            c._replace(point=p, normal=n, restitution=e, friction=mu))


SUBSETS = {"all": "every input", "states": "states + contact", "unknowns": "v, yaw, omega, P, n, eps, mu"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--summed", action="store_true", help="gradients of the losses built by ks_jax.sum_over_rows")
    args = ap.parse_args()
    n = args.rows
    _, last = bk.random_batch(n)
    first = bk.batch_first(last)
    path = "ks_jax.sum_over_rows" if args.summed else "jax.vmap(exchange)"
    print(f"gradients through {path}, {n} rows, jax {jax.__version__}, {bk.cpu_model()}; {args.repeats} rounds")
    calls = {}
    for name, row_loss in (("delta-V", bk.delta_v), ("residuals", bk.residuals)):
        loss = bk.batched_loss(row_loss, 0, chunked=True)
        fwd = jax.jit(lambda a, loss=loss: loss(a, None))
        jax.block_until_ready(fwd(first))
        calls[(name, "forward")] = lambda fwd=fwd: jax.block_until_ready(fwd(first))
        differentiated = bk.batched_loss(row_loss, 0, summed=True) if args.summed else loss
        for which in SUBSETS:
            part, rest = split(first, which)
            grad = jax.jit(jax.value_and_grad(
                lambda p, r, loss=differentiated, which=which: loss(merge(p, r, which), None)))
            seconds = bk.first_call(lambda grad=grad, part=part, rest=rest: jax.block_until_ready(grad(part, rest)))
            finite = all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(grad(part, rest)[1]))
            print(f"{name:9s} {SUBSETS[which]}: first call {seconds:.1f} s, finite {finite}", flush=True)
            calls[(name, which)] = lambda grad=grad, part=part, rest=rest: jax.block_until_ready(grad(part, rest))
    times = bk.rounds(calls, args.repeats)
    for (name, which), t in times.items():
        label = "forward" if which == "forward" else SUBSETS[which]
        print(f"{name:9s} {label:30s} {statistics.median(t) * 1e9 / n:7.0f} ns/row   / forward "
              f"{bk.ratio(times, (name, 'forward'), (name, which)):.2f}")


if __name__ == "__main__":
    main()
