"""The one way a pipeline of stages runs over a batch of rows: each stage vmapped, and on the CPU's path
(``backend.Plan``) fenced off from the next (docs/performance.md, "Stages").

A pipeline is a tuple of functions of one row: stage k is called with the row's inputs and then the
outputs of the stages before it, and the last stage's output is the result (``model.collision.stages``:
prepare, impulse, results). In one XLA program on a CPU, XLA's loop fusion copies every elementwise
producer into each loop that reads it: the input checks, the sines and cosines and the 3x3 algebra
that the impulse is made of would be evaluated again in the loop of each of the ~40 results. Fenced
apart, each stage's outputs are computed once and stored, as a separate jitted call would store them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..backend import Plan


def run(stages, args, in_axes=0, fenced=True, *, plan: Plan):
    """The result of the pipeline ``stages`` over a batch of rows, computed as ``plan`` says.

    args: a tuple of pytrees; in_axes: 0 (every leaf has the rows first), or a tuple of the same
    structure as ``args`` holding 0 or None per leaf (None: the same for every row); one row, unbatched:
    ``run_row``. fenced: True, each stage in a fence of its own on the CPU's path (``fence``); a number k, the first k
    stages only; False, none (one program that XLA may fuse freely, as it is everywhere but on a CPU). A fence costs
    tracing time under transformations (a fit's ``jax.jacfwd`` traces each conditional's branches again), so a caller
    that differentiates a few rows fences only what pays for itself."""
    count = len(stages) if fenced is True else int(fenced)
    outs = ()
    for k, stage in enumerate(stages):
        axes = (in_axes,) * len(args) if in_axes == 0 else tuple(in_axes)
        fn = jax.vmap(stage, in_axes=axes + (0,) * len(outs))
        if getattr(stage, "block_rows", 0) and plan.cpu:
            fn = in_blocks(fn, stage.block_rows, axes + (0,) * len(outs))
        outs += (fence(plan, fn, *args, *outs) if k < count else fn(*args, *outs),)
    return outs[-1]


def run_row(stages, args, fenced=0, plan: Plan | None = None):
    """The result of the pipeline ``stages`` on one unbatched row (``args``: a tuple of pytrees), its first
    ``fenced`` stages each fenced off from the later ones on ``plan``'s path (``fence``; a plan is needed only
    where ``fenced`` > 0): what ``run`` does for a batch."""
    outs = ()
    for k, stage in enumerate(stages):
        outs += (fence(plan, stage, *args, *outs) if k < fenced else stage(*args, *outs),)
    return outs[-1]


BLOCK_ROWS = 256  # rows per block of a ``blocked`` stage on the CPU's path


def blocked(stage, rows: int = BLOCK_ROWS):
    """``stage`` marked to run over a batch in blocks of ``rows`` rows on a CPU (``in_blocks``). For a stage
    that loops over many small steps (the motion to rest): each step's operations over a whole batch would
    stream it through memory, step after step; a block's stay in the cache."""

    def fn(*args):
        return stage(*args)

    fn.block_rows = rows
    return fn


def as_chunks(x, count, size):
    """The rows of ``x`` as (count, size, ...): ``count`` chunks of ``size`` rows, the last one padded
    with copies of the last row."""
    pad = count * size - x.shape[0]
    if pad:
        x = jnp.concatenate([x, jnp.broadcast_to(x[-1:], (pad,) + x.shape[1:])])
    return x.reshape((count, size) + x.shape[1:])


def in_blocks(fn, rows, in_axes):
    """``fn`` (vmapped over the rows of the leaves ``in_axes`` marks 0: per argument 0, None, or a tree of them)
    over blocks of ``rows`` rows, one after another (``lax.map``); the last block is padded with copies of the
    last row."""

    def over_blocks(*args):
        leaves, tree = jax.tree_util.tree_flatten(args)
        axes = []
        for x, a in zip(args, in_axes):
            count = len(jax.tree_util.tree_leaves(x))
            axes += [a] * count if a is None or isinstance(a, int) else \
                jax.tree_util.tree_leaves(a, is_leaf=lambda v: v is None)
        rows_of = [x.shape[0] for x, a in zip(leaves, axes) if a == 0]
        n = rows_of[0] if rows_of else 0
        if n <= rows:
            return fn(*args)
        count = -(-n // rows)
        batched = [as_chunks(x, count, rows) for x, a in zip(leaves, axes) if a == 0]

        def block(parts):
            parts = iter(parts)
            full = [next(parts) if a == 0 else x for x, a in zip(leaves, axes)]
            return fn(*jax.tree_util.tree_unflatten(tree, full))

        out = jax.lax.map(block, batched)
        return jax.tree_util.tree_map(lambda x: x.reshape((count * rows,) + x.shape[2:])[:n], out)

    return over_blocks


def fence(plan: Plan, fn, *operands):
    """``fn(*operands)``; on the CPU's path (``plan``) as the taken branch of a conditional whose predicate XLA
    cannot see through. XLA compiles a conditional's branches as computations of their own and fuses nothing
    across their boundary, so ``fn``'s outputs are computed in loops of their own and stored. The other
    branch returns zeros and never runs. On an accelerator's path ``fn(*operands)``."""
    if not plan.cpu:
        return fn(*operands)
    return fenced_by(jax.lax.optimization_barrier(jnp.bool_(True)), fn, *operands)


def fenced_by(pred, fn, *operands):
    """``fn(*operands)`` as the taken branch of ``lax.cond(pred, ...)``, ``pred`` True at run time (a
    loop's ``i >= 0``, or True through an optimization barrier). ``fn`` is traced once: the skipped
    branch takes the shapes of its zeros from the taken branch's trace."""
    traced = []

    def taken(*operands):
        out = fn(*operands)
        traced.append(jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x)), out))
        return out

    def skipped(*operands):
        shapes = traced[-1] if traced else jax.eval_shape(fn, *operands)  # a JAX that traces this branch first
        return jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)

    return jax.lax.cond(pred, taken, skipped, *operands)
