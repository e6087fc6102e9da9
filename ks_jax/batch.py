"""``exchange_batch``: the exchange over a batch of given inputs, computed the way ``sweep`` does.

A whole batch in one XLA program makes XLA's CPU loops stream batch-sized arrays through memory.
``exchange_batch`` computes the values of ``jax.vmap(exchange)`` in chunks of ``chunk`` rows
(cache-sized), each in three jitted calls whose outputs are stored once per row: the status and
sines/cosines (``exchange.prepare``), the impulse (``exchange.impulse_stage``), the results
(``exchange.results_stage``). The first call also copies the chunk's rows out of the full arrays
(into arrays that stay in the cache for the other two: each call reading its rows out of the
full arrays itself was 1.25x slower, benchmarks/RESULTS.md); the last chunk is aligned to the end
of the batch, so one compiled program serves every chunk.

The results are NumPy arrays, as ``sweep``'s are: each chunk is copied into them while the next
one is computed. NumPy backs large arrays with huge pages; a batch-sized result allocated by XLA
is first touched page by page, which cost more than the copy (benchmarks/RESULTS.md).

It is for values. To differentiate, vmap ``exchange``, whose own vmap rule runs the same three
stages in a loop over chunks inside one program (``ks_jax.exchange``'s module docstring);
``exchange_batch`` differs in giving NumPy results (or writing into earlier ones, ``out=``) and in
keeping no batch-sized XLA buffers.
"""

from __future__ import annotations

from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from .exchange import CHUNK_ROWS, prepare, results_stage, values_impulse_stage
from .types import Contact, ExchangeResult, State, Vehicle

DEFAULT_CHUNK = CHUNK_ROWS  # rows per chunk, as in ``sweep`` and ``exchange``'s vmap rule


def _rows(tree, start, size):
    return jax.tree_util.tree_map(lambda x: jax.lax.dynamic_slice_in_dim(x, start, size, 0), tree)


@lru_cache(maxsize=32)
def _stages(size, smoothing):
    def prep(args, start):  # the chunk's rows, cut once, and what ``prepare`` makes of them
        rows = _rows(args, start, size)
        return rows, jax.vmap(prepare)(*rows)

    def imp(rows, prepared):
        status, trig = prepared
        return jax.vmap(values_impulse_stage(smoothing))(*rows, status, trig)

    def res(rows, prepared, stage):
        return jax.vmap(results_stage)(*rows, prepared[0], stage)

    return jax.jit(prep), jax.jit(imp), jax.jit(res)


def exchange_batch(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
                   smoothing: float = 0.0, chunk: int = DEFAULT_CHUNK, out: ExchangeResult | None = None) -> ExchangeResult:
    """``jax.vmap(exchange)`` over a leading batch axis of every leaf, in chunks (module docstring).

    Every leaf has the batch size N first (a (3,) input becomes (N, 3)). Returns the
    ExchangeResult with a leading axis N, as NumPy arrays; rows with invalid inputs get their
    status code and NaN, as in ``exchange``. ``chunk``: rows per chunk (default 16384).
    ``out``: an ExchangeResult of writeable NumPy arrays of the result's shapes and dtypes (say an
    earlier result of a batch of the same size), written in place and returned. In a loop over
    batches this saves the first touch of ~520 bytes of new memory per row, whose cost on the
    benchmark machine varied from nothing to 0.7x the rest of the time (benchmarks/RESULTS.md).
    """
    if not 0.0 <= float(smoothing) < 1.0:
        raise ValueError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")
    if int(chunk) < 1:
        raise ValueError(f"chunk = {chunk}: chunk must be a positive number of rows")
    args = (vehicle1, state1, vehicle2, state2, contact)
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(args)):
        raise TypeError("exchange_batch computes values into NumPy arrays and cannot run under jax.jit, "
                        "jax.grad or jax.vmap; there, use jax.vmap(ks_jax.exchange)")
    sizes = {int(np.shape(x)[0]) if np.ndim(x) else None for x in jax.tree_util.tree_leaves(args)}
    if len(sizes) != 1 or None in sizes:
        raise ValueError("exchange_batch: every input needs the same leading batch axis; got sizes "
                         f"{sorted(map(str, sizes))}")
    n = sizes.pop()
    if n == 0:
        raise ValueError("exchange_batch: the batch is empty")
    given = [x for x in jax.tree_util.tree_leaves(args) if isinstance(x, np.ndarray)]
    args = jax.tree_util.tree_map(jnp.asarray, args)
    size = min(int(chunk), n)
    prep, imp, res = _stages(size, float(smoothing))
    target, out, treedef, pending = out, None, None, None

    def store(lo, start, chunk_result):  # rows lo.. of the batch from a chunk that starts at ``start``
        for o, x in zip(out, jax.tree_util.tree_leaves(chunk_result)):
            o[lo:start + size] = np.asarray(x)[lo - start:]

    for lo in range(0, n, size):
        start = min(lo, n - size)  # the last chunk ends at n (rows it repeats are not copied again)
        rows, prepared = prep(args, start)
        result = res(rows, prepared, imp(rows, prepared))
        if out is None:
            leaves, treedef = jax.tree_util.tree_flatten(result)
            if target is None:
                out = [np.empty((n,) + x.shape[1:], x.dtype) for x in leaves]
            else:
                out = _checked_out(target, result, n, given)
        if pending is not None:  # copy the chunk before while this one is computed
            store(*pending)
        pending = (lo, start, result)
    store(*pending)
    return jax.tree_util.tree_unflatten(treedef, out)


def _checked_out(target, result, n, inputs):
    """The leaves of ``out`` (``exchange_batch``), each checked against the chunk ``result``."""
    named, treedef = jax.tree_util.tree_flatten_with_path(result)
    try:
        leaves = treedef.flatten_up_to(target)
    except (TypeError, ValueError) as err:
        raise ValueError(f"exchange_batch: out must be an ExchangeResult like the result ({err})") from None
    for (path, x), o in zip(named, leaves):
        name, shape = "out" + jax.tree_util.keystr(path), (n,) + x.shape[1:]
        if not isinstance(o, np.ndarray) or o.shape != shape or o.dtype != x.dtype or not o.flags.writeable:
            got = f"{type(o).__name__} {getattr(o, 'dtype', '')}{list(np.shape(o))}"
            raise ValueError(f"exchange_batch: {name} = {got}: it must be a writeable NumPy array "
                             f"{x.dtype}{list(shape)}")
        if any(np.may_share_memory(o, i) for i in inputs):
            raise ValueError(f"exchange_batch: {name} shares memory with an input; it must not")
    return leaves
