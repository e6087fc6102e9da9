"""The exchange over a batch: ``exchange`` (the physics function with a vmap rule for large batches on a
CPU) and ``exchange_batch`` (values of a batch into NumPy arrays, chunk by chunk).

This is where the speed layer is wired into the physics: ``exchange`` is ``model.collision.exchange``
with ``chunks.batched_in_chunks``'s vmap rule, at each Python-number ``smoothing``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import compiler_options
from ..model import collision
from ..model.checks import check_smoothing
from ..model.types import Contact, ExchangeResult, State, Vehicle
from .chunks import CHUNK_ROWS, batched_in_chunks, cut
from .stages import run


@functools.lru_cache(maxsize=None)
def exchange_stages(smoothing: float):
    """``model.collision.stages(smoothing)``, one tuple per value (the programs built from it are
    cached by it)."""
    return collision.stages(smoothing)


@functools.lru_cache(maxsize=None)
def _batched(smoothing: float):
    plain = functools.partial(collision.exchange, smoothing=smoothing)
    return batched_in_chunks(plain, exchange_stages(smoothing))


@functools.wraps(collision.exchange)
def exchange(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
             smoothing=0.0) -> ExchangeResult:
    if isinstance(smoothing, (int, float)):
        check_smoothing(smoothing)
        return _batched(float(smoothing))(vehicle1, state1, vehicle2, state2, contact)
    return collision.exchange(vehicle1, state1, vehicle2, state2, contact, smoothing)  # a tau per row


@functools.lru_cache(maxsize=32)
def _chunk_program(size, smoothing, quick):
    """The program of one chunk of ``size`` rows starting at ``start``: the pipeline's stages fenced apart.
    ``quick``: compiled quickly (a batch of one chunk runs in milliseconds; compiling is most of its time)."""
    stages = exchange_stages(smoothing)
    return jax.jit(lambda args, start: run(stages, cut(args, start, size)), compiler_options=compiler_options(quick))


def exchange_batch(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
                   smoothing: float = 0.0, chunk: int = CHUNK_ROWS, out: ExchangeResult | None = None) -> ExchangeResult:
    """The values of ``jax.vmap(exchange)`` over a leading batch axis of every leaf, as NumPy arrays.

    Every leaf has the batch size N first (a (3,) input becomes (N, 3)). Returns the ExchangeResult with
    a leading axis N, as NumPy arrays; rows with invalid inputs get their status code and NaN, as in
    ``exchange``; a batch of no rows, results of no rows. The rows are computed in chunks of ``chunk``
    rows (one program per chunk size, the last chunk aligned to the end of the batch), each chunk
    copied into the results while the next is computed, so that no batch-sized array is ever held by
    XLA. A batch of at most ``CHUNK_ROWS`` rows is compiled quickly (``compilation.quick_jit``), a larger
    one with XLA's defaults. For values only: to differentiate, vmap ``exchange``.

    out: an ExchangeResult of writeable NumPy arrays of the result's shapes and dtypes (say an earlier
    result of a batch of the same size), written in place and returned: a loop over batches then touches
    no new memory.
    """
    check_smoothing(float(smoothing))
    if int(chunk) < 1:
        raise ValueError(f"chunk = {chunk}: chunk must be a positive number of rows")
    args, target = (vehicle1, state1, vehicle2, state2, contact), out
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(args)):
        raise TypeError("exchange_batch computes values into NumPy arrays and cannot run under jax.jit, "
                        "jax.grad or jax.vmap; there, use jax.vmap(ks_jax.exchange)")
    sizes = {int(np.shape(x)[0]) if np.ndim(x) else None for x in jax.tree_util.tree_leaves(args)}
    if len(sizes) != 1 or None in sizes:
        raise ValueError("exchange_batch: every input needs the same leading batch axis; got sizes "
                         f"{sorted(map(str, sizes))}")
    n = sizes.pop()
    given = [x for x in jax.tree_util.tree_leaves(args) if isinstance(x, np.ndarray)]
    args = jax.tree_util.tree_map(jnp.asarray, args)
    if n == 0:  # nothing to solve (a filtered batch may be empty): empty results, shaped and typed
        empty = jax.tree_util.tree_map(np.array, jax.vmap(functools.partial(collision.exchange,
                                                                            smoothing=float(smoothing)))(*args))
        if target is None:
            return empty
        _checked_out(target, empty, 0, given)
        return target
    size = min(int(chunk), n)
    program = _chunk_program(size, float(smoothing), n <= CHUNK_ROWS)
    leaves, treedef, pending = None, None, None

    def store(lo, start, result):  # rows lo.. of the batch from a chunk that starts at ``start``
        for o, x in zip(leaves, jax.tree_util.tree_leaves(result)):
            o[lo:start + size] = np.asarray(x)[lo - start:]

    for lo in range(0, n, size):
        start = min(lo, n - size)  # the last chunk ends at n (rows it repeats are not copied again)
        result = program(args, start)
        if leaves is None:
            chunk_leaves, treedef = jax.tree_util.tree_flatten(result)
            if target is None:
                leaves = [np.empty((n,) + x.shape[1:], x.dtype) for x in chunk_leaves]
            else:
                leaves = _checked_out(target, result, n, given)
        if pending is not None:  # copy the chunk before while this one is computed
            store(*pending)
        pending = (lo, start, result)
    store(*pending)
    return jax.tree_util.tree_unflatten(treedef, leaves)


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
