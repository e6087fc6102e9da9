"""Large batches in cache-sized chunks, and the vmap rule that gives ``jax.vmap(ks_jax.exchange)`` them
on a CPU (docs/performance.md, "Chunks").

Over a whole batch in one program, XLA's CPU loops stream the exchange's hundreds of intermediate
values through memory, batch-sized array after batch-sized array. In chunks of ``CHUNK_ROWS`` rows
(about 24 MiB of a stage's inputs and outputs, within a CPU's last-level cache), each through the
pipeline's stages fenced apart (``stages.run``), those arrays stay in the cache.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ..backend import CPU_CHUNK_ROWS, Plan
from ..limits import is_count
from .stages import run, run_row

CHUNK_ROWS = CPU_CHUNK_ROWS  # rows per chunk on a CPU


def check_chunk(chunk, who: str) -> int:
    """``chunk``, rows per chunk, refused by name unless it is a whole number >= 1: int() of "a" failed with
    int's own words, and of 2.5 gave 2 without a word."""
    if not is_count(chunk, 1):
        raise ValueError(f"{who}: chunk = {chunk!r}: chunk must be a positive number of rows (a whole number >= 1)")
    return int(chunk)


def cut(args, start, size, in_axes=0):
    """Rows start .. start + size of every batched leaf of ``args`` (``in_axes``: 0, every leaf batched, or
    a tree like ``args`` of 0 or None per leaf)."""
    if in_axes == 0:
        return jax.tree_util.tree_map(lambda x: jax.lax.dynamic_slice_in_dim(x, start, size, 0), args)
    return jax.tree_util.tree_map(
        lambda x, a: x if a is None else jax.lax.dynamic_slice_in_dim(x, start, size, 0), args, in_axes)


def in_chunks(stages, n, args, in_axes, size=None):
    """The pipeline ``stages`` over the n rows of ``args`` in a loop over chunks of ``size`` rows, inside
    one program, the CPU's way (its stages fenced apart). The last chunk ends at row n (it computes again some
    rows of the one before, which get the same values), so that every chunk has the same shape. ``size``:
    default ``CHUNK_ROWS``."""
    size = CHUNK_ROWS if size is None else size

    def chunk(i, out):
        start = jnp.minimum(i * size, n - size)
        result = run(stages, cut(args, start, size, in_axes), in_axes, plan=Plan("cpu"))
        return jax.tree_util.tree_map(lambda o, x: jax.lax.dynamic_update_slice_in_dim(o, x, start, 0), out, result)

    shapes = _row_shapes(stages, _row_structs(args, in_axes))
    out = jax.tree_util.tree_map(lambda s: jnp.zeros((n,) + s.shape, s.dtype), shapes)
    return jax.lax.fori_loop(0, -(-n // size), chunk, out)


def _row_structs(args, in_axes):
    return tuple(jax.tree_util.tree_map(
        lambda x, a: jax.ShapeDtypeStruct(x.shape[1:] if a == 0 else x.shape, x.dtype), args, in_axes))


@functools.lru_cache(maxsize=64)
def _row_shapes(stages, row):
    """The shapes and dtypes of the pipeline's result for one row: those of a chunk's rows, known without
    tracing the stages once more for every batch of the same row shapes."""
    return jax.eval_shape(lambda *a: run_row(stages, a), *row)


def batched_in_chunks(fn, stages, plan: Plan):
    """``fn`` (a function of arrays, equal to the pipeline ``stages``) with a vmap rule: over more than
    ``CHUNK_ROWS`` rows, on the CPU's path (``plan``) and one device, the rows run in chunks through the stages
    fenced apart (``in_chunks``); over one row, ``fn`` of that row unbatched (XLA compiles a batch of one row to a
    program many times the size of an unbatched row's); otherwise ``jax.vmap(fn)``. Every derivative is
    ``fn``'s, batched by ``jax.vmap`` (a custom vmap rule has no derivatives of its own): a loss that sums
    over many rows gets its gradient chunk by chunk from ``ks_jax.sum_over_rows``."""
    values = jax.custom_batching.custom_vmap(fn)

    @values.def_vmap
    def rule(n, in_batched, *args):
        in_axes = tuple(jax.tree_util.tree_map(lambda b: 0 if b else None, b) for b in in_batched)
        if n == 1:
            row = fn(*jax.tree_util.tree_map(lambda x, a: x if a is None else x[0], args, in_axes))
            out = jax.tree_util.tree_map(lambda x: x[None], row)
        elif n > CHUNK_ROWS and plan.cpu and jax.device_count() == 1:
            out = in_chunks(stages, n, args, in_axes)
        else:  # a short batch, or several devices (sharding is left to XLA)
            out = jax.vmap(fn, in_axes=in_axes)(*args)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    @jax.custom_jvp
    def batched(*args):
        return values(*args)

    @batched.defjvp
    def _(primals, tangents):
        return jax.jvp(fn, primals, tangents)

    return batched
