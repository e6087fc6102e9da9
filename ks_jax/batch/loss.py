"""``sum_over_rows``: a batched loss that is a sum over rows, whose derivatives are computed chunk by
chunk (docs/performance.md, "Gradients").
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from ..backend import Plan, plan_for
from .chunks import CHUNK_ROWS, check_chunk
from .stages import as_chunks
from .stages import fenced_by


def sum_over_rows(fn, in_axes=0, chunk: int = CHUNK_ROWS, plan: Plan | str | None = None):
    """``lambda *args: jnp.sum(jax.vmap(fn, in_axes)(*args))``, whose derivatives are computed chunk by chunk.

    The batched loss of a reconstruction or of a Monte Carlo study is a sum over rows of a row's loss
    ``fn(*row_args)``: a scalar, from ``ks_jax.exchange`` of the row, with rows whose status is not OK
    masked (as in any batched loss). Its value and forward are those of the loss written by hand; its
    gradient is cheaper. Through ``jax.vmap(exchange)``, reverse mode keeps the whole batch's
    intermediate values between the forward and the transposed pass. Here each chunk of ``chunk`` rows
    gets its value and gradient in one program (``jax.value_and_grad`` of the chunk's sum, its
    intermediate values staying in the cache), and reverse mode only scales that gradient.

    in_axes: 0 (every argument batched along its leading axis), or one entry per positional
    argument, 0 or None (None: the same for every row, as an evidence target or a shared parameter
    is; its gradient sums the rows'). Derivatives of any order and mode (``jax.grad``, ``jax.jvp``,
    ``jax.hessian``); a forward-mode derivative computes the gradient and dots it with the tangent.
    Only inputs that are differentiated get a gradient. On the CPU's path and one device over more than
    ``chunk`` rows, the gradient runs in chunks, each fenced off from the others (``stages.fenced_by``, so
    that XLA splits each chunk's loops over the cores); on an accelerator's path, on several devices (sharded
    inputs) or over ``chunk`` rows or fewer, it is ``jax.value_and_grad`` of the whole sum. ``plan``: a
    ``backend.Plan`` or its path ("cpu", "accelerator"); default, the path of JAX's default devices.
    """
    plan = plan_for(plan)
    chunk = check_chunk(chunk, "sum_over_rows")

    def axes_of(args):
        axes = (in_axes,) * len(args) if in_axes is None or isinstance(in_axes, int) else tuple(in_axes)
        if len(axes) != len(args):
            raise ValueError(f"sum_over_rows: in_axes = {in_axes!r} has {len(axes)} entries for {len(args)} arguments")
        for k, a in enumerate(axes):
            if a not in (0, None):
                raise ValueError(f"sum_over_rows: in_axes[{k}] = {a!r}: "
                                 "each entry must be 0 (batched) or None (shared)")
        if all(a is None for a in axes):
            raise ValueError("sum_over_rows: no argument is batched (in_axes needs an entry 0)")
        return axes

    def row_values(args):
        values = jax.vmap(fn, in_axes=axes_of(args))(*args)
        if values.ndim != 1:
            raise TypeError(f"sum_over_rows: fn returns shape {values.shape[1:]} per row; it must return a scalar")
        return values

    @jax.custom_jvp
    def summed(*args):
        return jnp.sum(row_values(args))

    def rule(primals, tangents):
        primals = jax.tree_util.tree_map(jnp.asarray, primals)  # a Python number has no dtype
        axes = axes_of(primals)
        leaves, treedef = jax.tree_util.tree_flatten(primals)
        batched = [a == 0 for a, arg in zip(axes, primals) for _ in jax.tree_util.tree_leaves(arg)]
        t_leaves = jax.tree_util.tree_leaves(tangents, is_leaf=lambda t: isinstance(t, SymbolicZero))
        wrt = [not isinstance(t, SymbolicZero) and jnp.issubdtype(x.dtype, jnp.inexact)
               for x, t in zip(leaves, t_leaves)]
        value, grads = _value_and_grad(row_values, treedef, leaves, batched, wrt, chunk, plan)
        dot = jnp.zeros_like(value)
        for g, t in zip(grads, (t for t, w in zip(t_leaves, wrt) if w)):
            dot = dot + jnp.sum(g * t)
        return value, dot

    summed.defjvp(rule, symbolic_zeros=True)
    return summed


def _merge(flags, a, b):
    """The list of ``flags``' length with the items of ``a`` where a flag is True, of ``b`` elsewhere."""
    a, b = iter(a), iter(b)
    return [next(a) if f else next(b) for f in flags]


def _value_and_grad(row_values, treedef, leaves, batched, wrt, chunk, plan):
    """The sum of ``row_values(args)`` over the rows and its gradient with respect to the leaves
    marked ``wrt`` (a list, in their order): in chunks of ``chunk`` rows on the CPU's path and one device."""
    diff = [x for x, w in zip(leaves, wrt) if w]
    fixed = [x for x, w in zip(leaves, wrt) if not w]

    def total(diff, fixed, keep=None):
        values = row_values(jax.tree_util.tree_unflatten(treedef, _merge(wrt, diff, fixed)))
        return jnp.sum(values if keep is None else jnp.where(keep, values, jnp.zeros((), values.dtype)))

    def whole(diff, fixed):
        return jax.value_and_grad(total)(diff, fixed)

    n = next(x.shape[0] for x, b in zip(leaves, batched) if b)
    if n <= chunk or jax.device_count() > 1:
        return whole(diff, fixed)

    def chunked(diff, fixed):
        count = -(-n // chunk)

        d_batched = [b for b, w in zip(batched, wrt) if w]
        f_batched = [b for b, w in zip(batched, wrt) if not w]
        d_rows = [as_chunks(x, count, chunk) for x, b in zip(diff, d_batched) if b]
        f_rows = [as_chunks(x, count, chunk) for x, b in zip(fixed, f_batched) if b]
        d_shared = [x for x, b in zip(diff, d_batched) if not b]
        f_shared = [x for x, b in zip(fixed, f_batched) if not b]
        keep = (jnp.arange(count * chunk) < n).reshape(count, chunk)

        def chunk_total(d_rows, d_shared, f_rows, keep):
            return total(_merge(d_batched, d_rows, d_shared), _merge(f_batched, f_rows, f_shared), keep)

        def body(x):
            i, d_rows, f_rows, keep = x
            # a conditional that is always taken: XLA runs the chunk's loops on every core
            return fenced_by(i >= 0, jax.value_and_grad(chunk_total, argnums=(0, 1)), d_rows, d_shared, f_rows, keep)

        values, (g_rows, g_shared) = jax.lax.map(body, (jnp.arange(count), d_rows, f_rows, keep))
        g_rows = [g.reshape((count * chunk,) + g.shape[2:])[:n] for g in g_rows]
        g_shared = [jnp.sum(g, axis=0) for g in g_shared]
        return jnp.sum(values), _merge(d_batched, g_rows, g_shared)

    return chunked(diff, fixed) if plan.cpu else whole(diff, fixed)
