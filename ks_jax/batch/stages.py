"""The one way a pipeline of stages runs over a batch of rows: each stage vmapped, and on a CPU
fenced off from the next (docs/performance.md, "Stages").

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

from ..backend import on_cpu


def run(stages, args, in_axes=0, fenced=True):
    """The result of the pipeline ``stages`` over a batch of rows.

    args: a tuple of pytrees; in_axes: 0 (every leaf has the rows first), or a tuple of the same
    structure as ``args`` holding 0 or None per leaf (None: the same for every row). None in place of
    the whole ``in_axes``: one row, unbatched. fenced: True, each stage in a fence of its own on a CPU
    (``fence``); a number k, the first k stages only; False, none (one program that XLA may fuse freely,
    as it is everywhere but on a CPU). A fence costs tracing time under transformations (a fit's
    ``jax.jacfwd`` traces each conditional's branches again), so a caller that differentiates a few rows
    fences only what pays for itself."""
    count = len(stages) if fenced is True else int(fenced)
    outs = ()
    for k, stage in enumerate(stages):
        if in_axes is None:
            fn = stage
        else:
            axes = (in_axes,) * len(args) if in_axes == 0 else tuple(in_axes)
            fn = jax.vmap(stage, in_axes=axes + (0,) * len(outs))
        outs += (fence(fn, *args, *outs) if k < count else fn(*args, *outs),)
    return outs[-1]


def fence(fn, *operands):
    """``fn(*operands)``; on a CPU as the taken branch of a conditional whose predicate XLA cannot see
    through. XLA compiles a conditional's branches as computations of their own and fuses nothing
    across their boundary, so ``fn``'s outputs are computed in loops of their own and stored. The other
    branch returns zeros and never runs. Elsewhere (a GPU) ``fn(*operands)``."""
    if not on_cpu():
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
