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

from ..backend import Plan, plan_for
from ..compilation import compiler_options
from ..model import collision
from ..model.checks import check_smoothing
from ..model.types import Contact, ExchangeResult, State, Vehicle
from .chunks import CHUNK_ROWS, batched_in_chunks, check_chunk, cut
from .stages import run


# a row's shape of each input that is not one number (docs/model.md, "Inputs"); every other input is ()
ROW_SHAPES = {"inertia": ((3,), (3, 3)), "position": ((3,),), "velocity": ((3,),), "angular_velocity": ((3,),),
              "point": ((3,),), "normal": ((3,),)}
ARGUMENTS = (("vehicle1", Vehicle), ("state1", State), ("vehicle2", Vehicle), ("state2", State), ("contact", Contact))


def check_rows(args, batch_axes: int, who: str):
    """Refuse inputs of the wrong kind or shape by name (TypeError, ValueError): a mass of shape (1,) would
    broadcast over the row's other inputs and give every result a shape and a status that say nothing of why,
    a position of (2,) would fail deep inside. ``batch_axes``: leading axes before a row's own (0 for ``exchange``,
    whose rows under ``jax.vmap`` are seen one at a time; 1 for ``exchange_batch``)."""
    for (name, kind), part in zip(ARGUMENTS, args):
        if not isinstance(part, kind):
            raise TypeError(f"{who}: {name} must be a {kind.__name__} (ks_jax.{kind.__name__}.create), got a "
                            f"{type(part).__name__}")
        for field, x in part._asdict().items():
            if isinstance(x, (str, bytes, list, tuple, dict)) or x is None:
                raise TypeError(f"{who}: {name}.{field} = {x!r}: must be an array or a number (SI; "
                                f"ks_jax.{kind.__name__}.create converts lists)")
            shape = tuple(np.shape(x))
            allowed = ROW_SHAPES.get(field, ((),))
            if len(shape) < batch_axes or shape[batch_axes:] not in allowed:
                rows = " or ".join(str(("N",) * batch_axes + s).replace("'", "") for s in allowed)
                raise ValueError(f"{who}: {name}.{field} has shape {shape}; it must be {rows}")


@functools.lru_cache(maxsize=None)
def exchange_stages(smoothing: float):
    """``model.collision.stages(smoothing)``, one tuple per value (the programs built from it are
    cached by it)."""
    return collision.stages(smoothing)


@functools.lru_cache(maxsize=None)
def _batched(smoothing: float, plan: Plan):
    plain = functools.partial(collision.exchange, smoothing=smoothing)
    return batched_in_chunks(plain, exchange_stages(smoothing), plan)


@functools.wraps(collision.exchange)
def exchange(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
             smoothing=0.0, plan: Plan | str | None = None) -> ExchangeResult:
    check_rows((vehicle1, state1, vehicle2, state2, contact), 0, "exchange")
    if isinstance(smoothing, (int, float)):
        check_smoothing(smoothing)
        return _batched(float(smoothing), plan_for(plan))(vehicle1, state1, vehicle2, state2, contact)
    return collision.exchange(vehicle1, state1, vehicle2, state2, contact, smoothing)  # a tau per row


exchange.__doc__ = (collision.exchange.__doc__ or "") + """
    plan: how ``jax.vmap(exchange)`` computes a large batch at a Python-number ``smoothing``: a ``backend.Plan``
    or its path ("cpu": in cache-sized chunks, the stages fenced apart, on one device; "accelerator": the whole
    batch in one program XLA fuses freely); default, the path of JAX's default devices. The values are the same.
"""


@functools.lru_cache(maxsize=32)
def _chunk_program(size, smoothing, quick, plan: Plan, platform=None):
    """The program of one chunk of ``size`` rows starting at ``start``: the pipeline's stages fenced apart on
    the CPU's path (``plan``, part of the key: a program traced for one path is not run on the other).
    ``quick``: compiled quickly for ``platform``, the rows' (a batch of one chunk runs in milliseconds; compiling
    is most of its time)."""
    stages = exchange_stages(smoothing)
    return jax.jit(lambda args, start: run(stages, cut(args, start, size), plan=plan),
                   compiler_options=compiler_options(quick, platform))


@functools.lru_cache(maxsize=32)
def _rows_program(smoothing, quick, plan: Plan, platform=None):
    """The program of a chunk given as its own arrays (rows copied to the device chunk by chunk); ``quick``,
    ``plan`` and ``platform`` as in ``_chunk_program``."""
    stages = exchange_stages(smoothing)
    return jax.jit(lambda args: run(stages, args, plan=plan), compiler_options=compiler_options(quick, platform))


def row_bytes(tree) -> int:
    """Bytes of one row of a batch-first pytree of arrays."""
    return sum(int(np.prod(np.shape(x)[1:], dtype=np.int64)) * np.dtype(x.dtype).itemsize
               for x in jax.tree_util.tree_leaves(tree))


def exchange_batch(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
                   smoothing: float = 0.0, chunk: int | None = None, out: ExchangeResult | None = None,
                   to_host: bool = True, plan: Plan | str | None = None) -> ExchangeResult:
    """The values of ``jax.vmap(exchange)`` over a leading batch axis of every leaf, as NumPy arrays.

    Every leaf has the batch size N first (a (3,) input becomes (N, 3)). Returns the ExchangeResult with
    a leading axis N, as NumPy arrays; rows with invalid inputs get their status code and NaN, as in
    ``exchange``; a batch of no rows, results of no rows. The rows are computed in chunks of ``chunk``
    rows (default the plan's, ``backend.Plan.rows``: 16384 on a CPU, from the free memory on an accelerator; one
    program per chunk size, the last chunk aligned to the end of the batch), each chunk copied into the
    results while the next is computed, so that no batch-sized array of intermediate values is ever held
    by XLA. On an accelerator, rows given as NumPy arrays go to the device chunk by chunk, and each
    chunk's results start their copy to the host as soon as they are computed. A batch of at most 16384
    rows is compiled quickly (``compilation.quick_options``), a larger one with XLA's defaults. For
    values only: to differentiate, vmap ``exchange``.

    out: an ExchangeResult of writeable NumPy arrays of the result's shapes and dtypes (say an earlier
    result of a batch of the same size), written in place and returned: a loop over batches then touches
    no new memory. to_host: False, the results stay on the device, as JAX arrays (for work that goes on
    there: a batch from device arrays then never crosses to the host). plan: a ``backend.Plan`` or its path
    ("cpu", "accelerator"); default, the path of the devices that hold the rows given as JAX arrays, or of JAX's
    default devices.
    """
    check_smoothing(float(smoothing))
    if chunk is not None:
        check_chunk(chunk, "exchange_batch")
    args, target = (vehicle1, state1, vehicle2, state2, contact), out
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(args)):
        raise TypeError("exchange_batch computes values into NumPy arrays and cannot run under jax.jit, "
                        "jax.grad or jax.vmap; there, use jax.vmap(ks_jax.exchange)")
    if target is not None and not to_host:
        raise ValueError("exchange_batch: out= is written on the host; it cannot go with to_host=False")
    check_rows(args, 1, "exchange_batch")
    sizes = {int(np.shape(x)[0]) if np.ndim(x) else None for x in jax.tree_util.tree_leaves(args)}
    if len(sizes) != 1 or None in sizes:
        raise ValueError("exchange_batch: every input needs the same leading batch axis; got sizes "
                         f"{sorted(map(str, sizes))}")
    n = sizes.pop()
    on = {d for x in jax.tree_util.tree_leaves(args) if isinstance(x, jax.Array) for d in x.devices()}
    plan = plan_for(plan, on or None)  # the path of the devices that hold the rows (or JAX's default devices)
    chunk = plan.rows(2 * row_bytes(args)) if chunk is None else chunk
    given = [x for x in jax.tree_util.tree_leaves(args) if isinstance(x, np.ndarray)]
    cpu = plan.cpu
    on_host = not cpu and len(given) == len(jax.tree_util.tree_leaves(args))  # sent to the device by chunks
    args = args if on_host else jax.tree_util.tree_map(jnp.asarray, args)
    if n == 0:  # nothing to solve (a filtered batch may be empty): empty results, shaped and typed
        # their shapes and dtypes from tracing alone: running the vmapped exchange eagerly on no rows compiled
        # each of its operations
        shapes = jax.eval_shape(jax.vmap(functools.partial(collision.exchange, smoothing=float(smoothing))), *args)
        empty = jax.tree_util.tree_map(lambda s: np.zeros(s.shape, s.dtype), shapes)
        if not to_host:
            return jax.tree_util.tree_map(jnp.asarray, empty)
        if target is None:
            return empty
        _checked_out(target, empty, 0, given)
        return target
    size = min(int(chunk), n)
    platform = next(iter(on)).platform if on else jax.default_backend()  # where the rows are computed
    if on_host:
        rows = _rows_program(float(smoothing), n <= CHUNK_ROWS, plan, platform)
        program = lambda a, start: rows(jax.tree_util.tree_map(lambda x: x[start:start + size], a))  # noqa: E731
    else:
        program = _chunk_program(size, float(smoothing), n <= CHUNK_ROWS, plan, platform)
    leaves, treedef, pending, kept = None, None, None, []

    def store(lo, start, result):  # rows lo.. of the batch from a chunk that starts at ``start``
        for o, x in zip(leaves, jax.tree_util.tree_leaves(result)):
            o[lo:start + size] = np.asarray(x)[lo - start:]

    for lo in range(0, n, size):
        start = min(lo, n - size)  # the last chunk ends at n (rows it repeats are not copied again)
        result = program(args, start)
        if not to_host:
            kept.append(result if lo == start else jax.tree_util.tree_map(lambda x: x[lo - start:], result))
            continue
        if not cpu:  # start the copy to the host now: it runs while the next chunk is computed
            for x in jax.tree_util.tree_leaves(result):
                x.copy_to_host_async()
        if leaves is None:
            chunk_leaves, treedef = jax.tree_util.tree_flatten(result)
            if target is None:
                leaves = [np.empty((n,) + x.shape[1:], x.dtype) for x in chunk_leaves]
            else:
                leaves = _checked_out(target, result, n, given)
        if pending is not None:  # copy the chunk before while this one is computed
            store(*pending)
        pending = (lo, start, result)
    if not to_host:
        return kept[0] if len(kept) == 1 else jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *kept)
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
