"""``exchange_batch``: the exchange over a batch of given inputs, computed the way ``sweep`` does.

``jax.jit(jax.vmap(exchange))`` over a whole batch is correct and differentiable, but on a CPU
XLA turns the ~40 results into ~120 elementwise loops, each streaming batch-sized arrays through
memory. ``exchange_batch`` computes the same values in chunks of ``chunk`` rows (cache-sized),
each in three jitted calls whose outputs are stored once per row (the last writes its rows into
the result in place): the status and sines/cosines
(``exchange.prepare``), the impulse (``exchange.impulse_stage``), the results
(``exchange.results_stage``). That is 1.7-2.1x the rate of the single call on a million rows
(benchmarks/RESULTS.md). Each chunk is read out of the full arrays inside the jitted calls; the
last chunk is aligned to the end of the batch, so one compiled program serves every chunk.

It is for values. To differentiate, vmap ``exchange`` (``jax.grad`` of ``exchange_batch`` also
works, chunk by chunk, but gains nothing).
"""

from __future__ import annotations

from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from .exchange import impulse_stage, prepare, results_stage
from .types import Contact, ExchangeResult, State, Vehicle

DEFAULT_CHUNK = 1 << 14  # rows: the stages' arrays stay in a 2 MiB L2 cache (as in ``sweep``)


def _rows(tree, start, size):
    return jax.tree_util.tree_map(lambda x: jax.lax.dynamic_slice_in_dim(x, start, size, 0), tree)


@lru_cache(maxsize=32)
def _stages(size, smoothing):
    def prep(args, start):
        return jax.vmap(prepare)(*_rows(args, start, size))

    def imp(args, start, prepared):
        status, trig = prepared
        return jax.vmap(lambda *a: impulse_stage(*a[:5], smoothing, *a[5:]))(*_rows(args, start, size), status, trig)

    def res(args, start, prepared, stage, out):
        chunk = jax.vmap(results_stage)(*_rows(args, start, size), prepared[0], stage)
        return jax.tree_util.tree_map(lambda o, c: jax.lax.dynamic_update_slice_in_dim(o, c, start, 0), out, chunk)

    def res_first(args, prepared, stage, n):  # allocates the result (n rows) around the first chunk
        chunk = jax.vmap(results_stage)(*_rows(args, 0, size), prepared[0], stage)
        return jax.tree_util.tree_map(
            lambda c: jax.lax.dynamic_update_slice_in_dim(jnp.zeros((n,) + c.shape[1:], c.dtype), c, 0, 0), chunk)

    return (jax.jit(prep), jax.jit(imp), jax.jit(res, donate_argnums=4),
            jax.jit(res_first, static_argnames="n"))


def exchange_batch(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
                   smoothing: float = 0.0, chunk: int = DEFAULT_CHUNK) -> ExchangeResult:
    """``jax.vmap(exchange)`` over a leading batch axis of every leaf, in chunks (module docstring).

    Every leaf has the batch size N first (a (3,) input becomes (N, 3)). Returns the
    ExchangeResult with a leading axis N, as jax arrays; rows with invalid inputs get their status
    code and NaN, as in ``exchange``. ``chunk``: rows per chunk (default 16384).
    """
    if not 0.0 <= float(smoothing) < 1.0:
        raise ValueError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")
    if int(chunk) < 1:
        raise ValueError(f"chunk = {chunk}: chunk must be a positive number of rows")
    args = (vehicle1, state1, vehicle2, state2, contact)
    sizes = {int(np.shape(x)[0]) if np.ndim(x) else None for x in jax.tree_util.tree_leaves(args)}
    if len(sizes) != 1 or None in sizes:
        raise ValueError("exchange_batch: every input needs the same leading batch axis; got sizes "
                         f"{sorted(map(str, sizes))}")
    n = sizes.pop()
    if n == 0:
        raise ValueError("exchange_batch: the batch is empty")
    args = jax.tree_util.tree_map(jnp.asarray, args)
    size = min(int(chunk), n)
    prep, imp, res, res_first = _stages(size, float(smoothing))
    out = None
    for lo in range(0, n, size):
        start = min(lo, n - size)  # the last chunk ends at n (rows it repeats get the same values)
        prepared = prep(args, start)
        stage = imp(args, start, prepared)
        out = res_first(args, prepared, stage, n=n) if out is None else res(args, start, prepared, stage, out)
    return out
