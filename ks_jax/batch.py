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

``sum_over_rows`` builds a batched loss that is a sum over rows, whose gradient takes each chunk's
value and gradient in one program (its docstring).
"""

from __future__ import annotations

from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from .exchange import CHUNK_ROWS, _fenced, as_chunks, exchange, platform_dependent, prepare, results_stage, values_impulse_stage
from .stored import stored_jit
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

    return tuple(stored_jit(fn, (size, smoothing)) for fn in (prep, imp, res))  # kept by ``keep_programs``


def exchange_batch(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
                   smoothing: float = 0.0, chunk: int = DEFAULT_CHUNK, out: ExchangeResult | None = None) -> ExchangeResult:
    """``jax.vmap(exchange)`` over a leading batch axis of every leaf, in chunks (module docstring).

    Every leaf has the batch size N first (a (3,) input becomes (N, 3)). Returns the
    ExchangeResult with a leading axis N, as NumPy arrays; rows with invalid inputs get their
    status code and NaN, as in ``exchange``; a batch of no rows, results of no rows.
    ``chunk``: rows per chunk (default 16384).
    ``out``: an ExchangeResult of writeable NumPy arrays of the result's shapes and dtypes (say an
    earlier result of a batch of the same size), written in place and returned. In a loop over
    batches this saves the first touch of ~520 bytes of new memory per row, whose cost on the
    benchmark machine varied from nothing to 0.7x the rest of the time (benchmarks/RESULTS.md).
    """
    if not 0.0 <= float(smoothing) < 1.0:
        raise ValueError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")
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
        empty = jax.tree_util.tree_map(np.array, jax.vmap(lambda *a: exchange(*a, smoothing=smoothing))(*args))
        if target is None:
            return empty
        _checked_out(target, empty, 0, given)
        return target
    size = min(int(chunk), n)
    prep, imp, res = _stages(size, float(smoothing))
    out, treedef, pending = None, None, None

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


def sum_over_rows(fn, in_axes=0, chunk: int = DEFAULT_CHUNK):
    """``lambda *args: jnp.sum(jax.vmap(fn, in_axes)(*args))``, whose derivatives are computed chunk by chunk.

    The batched loss of a reconstruction or of a Monte Carlo study is a sum over rows of a row's loss
    ``fn(*row_args)``: a scalar, from ``ks_jax.exchange`` of the row, with rows whose status is not OK
    masked (as in any batched loss). Built here, its value and its forward are those of the loss
    written by hand (the forward is ``jax.vmap(exchange)``'s chunked rule). Its gradient is cheaper.
    Through ``jax.vmap(exchange)``, reverse mode runs the batch's forward, then each chunk's forward
    again, then the transposed stages, storing the stages' intermediate values between them. Here
    each chunk of ``chunk`` rows gets its value and gradient in one program (``jax.value_and_grad``
    of the chunk's sum, its intermediate values staying in the cache), and reverse mode only scales
    that gradient: 1.5-1.8x faster at 2^20 rows on the benchmark machine (benchmarks/RESULTS.md).

    in_axes: 0 (every argument batched along its leading axis), or one entry per positional
    argument, 0 or None (None: the same for every row, as an evidence target or a shared parameter
    is; its gradient sums the rows'). Derivatives of any order and mode (``jax.grad``, ``jax.jvp``,
    ``jax.hessian``); a forward-mode derivative computes the gradient and dots it with the tangent.
    Only inputs that are differentiated get a gradient. On one CPU device over more than ``chunk``
    rows, the gradient runs in chunks, each in a conditional (as ``exchange``'s chunks do, so that
    XLA splits its loops over the cores); on a GPU, on several devices (sharded inputs) or over
    ``chunk`` rows or fewer, it is ``jax.value_and_grad`` of the whole sum.
    """
    if int(chunk) < 1:
        raise ValueError(f"chunk = {chunk}: chunk must be a positive number of rows")
    chunk = int(chunk)

    def axes_of(args):
        axes = (in_axes,) * len(args) if in_axes is None or isinstance(in_axes, int) else tuple(in_axes)
        if len(axes) != len(args):
            raise ValueError(f"sum_over_rows: in_axes = {in_axes!r} has {len(axes)} entries for {len(args)} arguments")
        for k, a in enumerate(axes):
            if a not in (0, None):
                raise ValueError(f"sum_over_rows: in_axes[{k}] = {a!r}: each entry must be 0 (batched) or None (shared)")
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
        wrt = [not isinstance(t, SymbolicZero) and jnp.issubdtype(x.dtype, jnp.inexact) for x, t in zip(leaves, t_leaves)]
        value, grads = _value_and_grad(row_values, treedef, leaves, batched, wrt, chunk)
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


def _value_and_grad(row_values, treedef, leaves, batched, wrt, chunk):
    """The sum of ``row_values(args)`` over the rows and its gradient with respect to the leaves
    marked ``wrt`` (a list, in their order): in chunks of ``chunk`` rows on one CPU device."""
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
            # a conditional that is always taken (exchange._fenced): XLA runs its loops on every core
            return _fenced(i >= 0, jax.value_and_grad(chunk_total, argnums=(0, 1)), d_rows, d_shared, f_rows, keep)

        values, (g_rows, g_shared) = jax.lax.map(body, (jnp.arange(count), d_rows, f_rows, keep))
        g_rows = [g.reshape((count * chunk,) + g.shape[2:])[:n] for g in g_rows]
        g_shared = [jnp.sum(g, axis=0) for g in g_shared]
        return jnp.sum(values), _merge(d_batched, g_rows, g_shared)

    return platform_dependent(diff, fixed, cpu=chunked, default=whole)
