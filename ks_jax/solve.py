"""Solve cases: CaseInputs -> ExchangeResult, batched over the cases of a file."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import numpy as np

from .case import Case, CaseInputs, as_arrays, move_scene, scene_origin, speed_status, to_pytrees
from .case import farthest_out_of_scale, warn_far_from_origin
from .derived import mask_invalid
from .exchange import exchange
from .quick import quick_jit
from .types import INVALID_OVERFLOW, ExchangeResult, status_text


def solve_inputs(inputs: CaseInputs, auto_point: bool = False, auto_normal: bool = False,
                 smoothing=0.0) -> ExchangeResult:
    """One case's results from its inputs (pure, unbatched; jit/vmap/grad at the edge).

    ``auto_point``/``auto_normal`` (static) select automatic contact (MODEL.md section 5) for
    the centroid and/or the normal; otherwise the exchange is at the case state.
    A negative ``speed`` (reachable by ``set_input``, a sweep or a fit, never by a case file) gives
    status INVALID_SPEED_1/2 and NaN results (``case.speed_status``), unless the exchange found
    another invalid input first.
    """
    v1, s1, v2, s2, contact = to_pytrees(inputs)
    if auto_point or auto_normal:
        from .geometry import automatic_exchange

        result = automatic_exchange(v1, s1, v2, s2, contact, inputs.contact.normal_pitch,
                                    auto_point=auto_point, auto_normal=auto_normal, smoothing=smoothing)
    else:
        result = exchange(v1, s1, v2, s2, contact, smoothing)
    return with_speed_status(inputs, result)


def with_speed_status(inputs: CaseInputs, result: ExchangeResult) -> ExchangeResult:
    """``result`` of ``inputs`` with ``case.speed_status`` applied: that status and NaN results
    where a negative speed makes the row invalid."""
    status = speed_status(inputs, result.contact.status)
    result = mask_invalid(result, status == result.contact.status)  # NaN where the speed made it invalid
    return result._replace(contact=result.contact._replace(status=status))


def _rows(fn, *args):
    """``fn`` over the leading axis of ``args``. One case unbatched: XLA compiled the vmapped program
    for a batch of one 3-4x slower than for two rows or for no batch axis (6.1 against 1.5 s
    explicit, 17.5 against 5.9 s automatic, 2026-11-22). The exchange's own vmap rule now computes
    one row unbatched, which removed most of that; the stages of automatic contact still compile
    slightly smaller here (4,947 against 5,206 instructions)."""
    if jax.tree_util.tree_leaves(args)[0].shape[0] == 1:
        row = fn(*jax.tree_util.tree_map(lambda x: x[0], args))
        return jax.tree_util.tree_map(lambda x: x[None], row)
    return jax.vmap(fn)(*args)


# a file's few cases: compile time is most of the time (``ks_jax.quick``)
@partial(quick_jit, static_argnames=("smoothing",))
def _solve_explicit(inputs, smoothing):
    return _rows(lambda x: solve_inputs(x, False, False, smoothing), inputs)


def auto_status(inputs: CaseInputs):
    """() int32: the first stage of automatic contact, ``exchange.input_status`` of one row."""
    from .exchange import input_status

    return input_status(*to_pytrees(inputs))


def auto_contact(inputs: CaseInputs, status, auto_point: bool, auto_normal: bool):
    """The second stage: ``geometry.automatic_stage`` of one row, given its ``auto_status``."""
    from .geometry import automatic_stage

    return automatic_stage(*to_pytrees(inputs), inputs.contact.normal_pitch, status, auto_point=auto_point,
                           auto_normal=auto_normal)


def auto_exchange(inputs: CaseInputs, status, auto, smoothing=0.0) -> ExchangeResult:
    """The third stage: the exchange at ``auto`` (``auto_contact``), as ``solve_inputs`` returns it.
    The three in one program are ``solve_inputs`` with automatic contact; run as three compiled calls
    (``_solve_batch``, ``ks_jax.sweep``) they compile and run faster (``geometry.automatic_exchange``)."""
    from .geometry import exchange_at_contact

    return with_speed_status(inputs, exchange_at_contact(*to_pytrees(inputs), status, auto, smoothing))


_auto_status = quick_jit(lambda inputs: _rows(auto_status, inputs))
_auto_contact = quick_jit(lambda inputs, status, auto_point, auto_normal: _rows(
    lambda x, st: auto_contact(x, st, auto_point, auto_normal), inputs, status), static_argnums=(2, 3))
_auto_exchange = quick_jit(lambda inputs, status, auto, smoothing: _rows(
    lambda x, st, a: auto_exchange(x, st, a, smoothing), inputs, status, auto), static_argnums=(3,))


def _solve_batch(inputs, smoothing, auto_point, auto_normal):
    """``solve_inputs`` of every row. Automatic contact runs as three compiled calls, status, contact
    and exchange (``geometry.automatic_exchange`` says why): one program took 5.7 s to compile,
    the three 2.5 s (benchmarks/RESULTS.md)."""
    if not (auto_point or auto_normal):
        return _solve_explicit(inputs, smoothing)
    status = _auto_status(inputs)
    return _auto_exchange(inputs, status, _auto_contact(inputs, status, auto_point, auto_normal), smoothing)


@dataclass
class Solution:
    """A solved case: ``result`` is an ExchangeResult of NumPy arrays (None for an invalid case)."""

    case: Case
    result: ExchangeResult | None
    status: str

    def to_dict(self) -> dict:
        """MODEL.md section 4 as plain JSON-ready data (SI; NaN -> None)."""
        from .report import solution_dict

        return solution_dict(self)


def _status(case: Case, code) -> str:
    """The status words of a solved case; an overflow also names the input farthest out of scale."""
    text = status_text(code)
    if int(code) == INVALID_OVERFLOW:
        text += f"; the input farthest out of scale: {farthest_out_of_scale(case.inputs)}"
    return text


def solve(cases, smoothing: float = 0.0):
    """Solve a Case (-> Solution) or a list of cases (-> list of Solution).

    Valid cases are solved together in one vmapped call per contact mode; an invalid case
    (bad input in a multi-case file) gets status "invalid: <reason>" and no numbers.
    In float32 (JAX's default) a case more than ``case.FAR_IN_FLOAT32`` (1 km) from the origin is solved
    about its CGs' midpoint (``case.scene_origin``), and its ``contact.point`` is float64.
    """
    single = isinstance(cases, Case)
    cases = [cases] if single else list(cases) if isinstance(cases, (list, tuple)) else None
    if cases is None or not all(isinstance(c, Case) for c in cases):
        raise TypeError("solve takes a Case or a list of them: ks_jax.load_case(path) reads a case file")
    if not 0.0 <= smoothing < 1.0:
        raise ValueError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")
    out: list[Solution | None] = [None] * len(cases)
    groups: dict[tuple, list[int]] = {}
    for i, c in enumerate(cases):
        if c.valid:
            groups.setdefault((c.auto_point, c.auto_normal), []).append(i)
        else:
            out[i] = Solution(c, None, c.error if c.error.startswith("invalid") else f"invalid: {c.error}")
    for (auto_point, auto_normal), idx in groups.items():
        stacked = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *[cases[i].inputs for i in idx])
        origin = scene_origin(stacked)  # float32 far from the origin: solved about the CGs' midpoint
        if origin is not None:
            stacked = move_scene(stacked, origin, auto_point)
        warn_far_from_origin(stacked, what="a case", about="the origin" if origin is None else "its CGs' midpoint",
                             auto_point=auto_point)
        res = _solve_batch(as_arrays(stacked), float(smoothing), auto_point, auto_normal)
        res = jax.tree_util.tree_map(np.asarray, res)
        if origin is not None:
            point = res.contact.point.astype(np.float64)
            point[:, :2] += origin
            res = res._replace(contact=res.contact._replace(point=point))
        for k, i in enumerate(idx):
            row = jax.tree_util.tree_map(lambda x: x[k], res)
            out[i] = Solution(cases[i], row, _status(cases[i], row.contact.status))
    return out[0] if single else out
