"""A case's pipeline: its inputs to the exchange's results (and the motion to rest), as stages of one row
(``stages``, run over rows by ``batch.stages.run``), and as a pure function of one case's inputs
(``solve_inputs``)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..batch.stages import blocked, run_row
from ..case import CaseInputs, Motion, to_pytrees
from ..model import collision
from ..model.contact import automatic_stage, exchange_at_contact
from ..model.checks import input_status
from ..model.types import OK, ExchangeResult
from .rest import to_rest
from .rules import speed_status, with_speed_status


def solve_inputs(inputs: CaseInputs, auto_point: bool = False, auto_normal: bool = False,
                 smoothing=0.0, pole: bool = False, motion: Motion | None = None) -> ExchangeResult:
    """One case's results from its inputs (pure, unbatched; jit, vmap and grad at the edge).

    ``auto_point``/``auto_normal`` (static) select automatic contact for the centroid and/or the normal;
    otherwise the exchange is at the case state. ``pole`` (static): vehicle 2 is a pole, which automatic
    contact meets as a disc (``Case.pole``). ``motion`` (static, ``Case.motion``): where the inputs have a
    ``road``, how the vehicles' motion to rest is integrated (the result's ``rest``). A negative ``speed``
    (reachable by ``set_input``, a sweep or a fit, never by a case file) gives status INVALID_SPEED_1/2 and NaN
    results (``speed_status``), unless another input breaks a rule first.

    Of the pipeline's stages (``stages``) only automatic contact's first, the input rules, is fenced off
    (``batch.stages.run_row``): every later loop reads the rules, and XLA would derive them again inside each
    loop that reads a stand-in input, in a program over twice the size to compile. The others are fused
    freely: a fit differentiates this function, and a fence costs tracing time under ``jax.jacfwd``."""
    return run_row(stages(auto_point, auto_normal, smoothing, pole, motion), (inputs,),
                   fenced=1 if auto_point or auto_normal else 0)


def stages(auto_point: bool, auto_normal: bool, smoothing=0.0, pole: bool = False, motion: Motion | None = None):
    """The case's pipeline, functions of a row's ``CaseInputs`` and the outputs of the stages before
    (``ks_jax.batch.stages.run``): the exchange's own stages (``model.collision.stages``) at a given
    contact; for automatic contact, the input rules, the contact (``model.contact.automatic_stage``)
    and the exchange there (``exchange_at_contact``). ``smoothing``: a Python number or an array. With
    ``motion`` (a ``case.Motion``), the last stage moves the vehicles on from the exchange to rest
    (``to_rest``): the result's ``rest``."""
    exchange_stages = _exchange_stages(auto_point, auto_normal, smoothing, pole)
    if motion is None:
        return exchange_stages
    *first, last = exchange_stages
    auto = auto_point or auto_normal

    def exchange_and_rest(inputs, *earlier):
        result = last(inputs, *earlier)
        states = to_pytrees(inputs)[1:4:2]
        if auto:  # the vehicles at the exchange: where automatic contact put them, where it could
            status, found = earlier
            ok = status == OK
            states = tuple(jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), s_auto, s)
                           for s_auto, s in zip((found.state1, found.state2), states))
        return to_rest(inputs, result, states, motion, smoothing)

    return (*first, blocked(exchange_and_rest))


def _exchange_stages(auto_point, auto_normal, smoothing, pole):
    if auto_point or auto_normal:
        def rules(inputs):
            return input_status(*to_pytrees(inputs))

        def contact(inputs, status):
            return automatic_stage(*to_pytrees(inputs), inputs.contact.normal_pitch, status,
                                   auto_point=auto_point, auto_normal=auto_normal, pole=pole)

        def exchange(inputs, status, auto):
            return with_speed_status(inputs, exchange_at_contact(*to_pytrees(inputs), status, auto, smoothing))

        return rules, contact, exchange
    prepare, impulse, results = collision.stages(smoothing)

    def prepared(inputs):
        p = prepare(*to_pytrees(inputs))
        return p._replace(status=speed_status(inputs, p.status))

    def found(inputs, p):
        return impulse(*to_pytrees(inputs), p)

    def derived(inputs, p, j):
        return results(*to_pytrees(inputs), p, j)

    return prepared, found, derived

