"""What the results stage's unused outputs cost the chunked gradient (tried; the library is unchanged).

    .venv/bin/python benchmarks/tried/pruned_results_stage.py [--rows 1048576] [--repeats 5]

The delta-V loss of bench_kernel.py reads one result per vehicle, but the reverse pass of
``jax.vmap(exchange)`` transposes the results stage for all of them: the cotangents of the unused ones
reach the loop over chunks as arrays of zeros, which XLA still multiplies through. This script times
``jax.value_and_grad`` of that loss twice in the same rounds: with the library's results stage, and with
one that computes only ``delta_v_magnitude`` (zeros elsewhere; patched into ``ks_jax.exchange`` for the
run), the bound on what pruning the unused outputs' derivatives could give.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_kernel as bk  # noqa: E402

import ks_jax  # noqa: E402, F401  (ks_jax.exchange is the function; the module is in sys.modules)

EX = sys.modules["ks_jax.exchange"]
LIBRARY = EX.results_stage


def only_delta_v(vehicle1, state1, vehicle2, state2, contact, status, stage):
    """``results_stage`` with every result zero but the two delta-V magnitudes and the status."""
    full = jax.eval_shape(LIBRARY, vehicle1, state1, vehicle2, state2, contact, status, stage)
    zero = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), full)
    ok = status == 0
    j_mag = EX.la.safe_norm(EX.la.array(stage.j))
    v1 = zero.vehicles[0]._replace(delta_v_magnitude=jnp.where(ok, j_mag / vehicle1.mass, jnp.nan))
    v2 = zero.vehicles[1]._replace(delta_v_magnitude=jnp.where(ok, j_mag / vehicle2.mass, jnp.nan))
    code = jnp.where(ok & ~stage.approaching, 1, status)
    return zero._replace(vehicles=(v1, v2), contact=zero.contact._replace(status=code))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    n = args.rows
    _, last = bk.random_batch(n)
    first = bk.batch_first(last)
    floats = tuple(first[:5])
    status = jax.jit(jax.vmap(EX.input_status))(*first)
    fns, values = {}, {}
    for label, stage in (("library", LIBRARY), ("pruned", only_delta_v)):
        EX.results_stage = stage  # read when the programs below are traced
        loss = bk.batched_loss(bk.delta_v, 0, chunked=True)
        fwd, grad = jax.jit(loss), jax.jit(jax.value_and_grad(loss))
        values[label] = float(jax.block_until_ready(grad(floats, status))[0])
        jax.block_until_ready(fwd(floats, status))
        fns[label + " forward"] = lambda fwd=fwd: jax.block_until_ready(fwd(floats, status))
        fns[label + " gradient"] = lambda grad=grad: jax.block_until_ready(grad(floats, status))
    EX.results_stage = LIBRARY
    times = bk.rounds(fns, args.repeats)
    print(f"delta-V loss, {n} rows, jax {jax.__version__}, {bk.cpu_model()}; same value: "
          f"{values['library'] == values['pruned']}")
    for key, t in times.items():
        print(f"  {key:18s} {statistics.median(t) / n * 1e9:7.1f} ns per row")
    print(f"gradient / forward: library {bk.ratio(times, 'library forward', 'library gradient'):.2f}, pruned "
          f"{bk.ratio(times, 'pruned forward', 'pruned gradient'):.2f}; pruned gradient / library gradient "
          f"{1 / bk.ratio(times, 'pruned gradient', 'library gradient'):.3f}")


if __name__ == "__main__":
    main()
