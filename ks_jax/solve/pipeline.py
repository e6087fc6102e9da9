"""A case's pipeline: its inputs to the exchange's results (and the motion to rest), as stages of one row
(``stages``, run over rows by ``batch.stages.run``), and as a pure function of one case's inputs
(``solve_inputs``)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..backend import Plan, plan_for
from ..batch.stages import blocked, run_row
from ..case import CaseInputs, Motion, body_states, check_inputs, follow_tows, to_pytrees
from ..model import collision
from ..model import linalg as la
from ..model.contact import advance, automatic_stage, exchange_at_contact
from ..model.checks import input_status
from ..model.results import ees_pair, energy_loss_rounding, mask_invalid
from ..model.types import INVALID_NONFINITE, OK, ExchangeResult, VehicleResult
from .rest import approaches, states_at, to_rest
from .rules import speed_status, with_speed_status


def solve_inputs(inputs: CaseInputs, auto_point: bool = False, auto_normal: bool = False,
                 smoothing=0.0, pole: bool = False, motion: Motion | None = None, between=(0, 1),
                 plan: Plan | str | None = None) -> ExchangeResult:
    """One case's results from its inputs (pure, unbatched; jit, vmap and grad at the edge).

    ``auto_point``/``auto_normal`` (static) select automatic contact for the centroid and/or the normal;
    otherwise the exchange is at the case state. ``pole`` (static): vehicle 2 is a pole, which automatic
    contact meets as a disc (``Case.pole``). ``motion`` (static, ``Case.motion``): where the inputs have a
    ``road``, how the vehicles' motion to rest is integrated (the result's ``rest``). ``between`` (static,
    ``Case.between``): the first exchange's bodies; the result's ``vehicles`` has one entry per body of
    ``inputs.vehicles`` (``in_body_order``). A negative ``speed``
    (reachable by ``set_input``, a sweep or a fit, never by a case file) gives status INVALID_SPEED_1/2 and NaN
    results (``speed_status``), unless another input breaks a rule first.

    Of the pipeline's stages (``stages``) only automatic contact's first, the input rules, is fenced off
    (``batch.stages.run_row``): every later loop reads the rules, and XLA would derive them again inside each
    loop that reads a stand-in input, in a program over twice the size to compile. The others are fused
    freely: a fit differentiates this function, and a fence costs tracing time under ``jax.jacfwd``. ``plan``
    (static): a ``backend.Plan`` or its path ("cpu", "accelerator"), whose fence that is, and whose path says how the
    watched motion carries its state (``stages``); default, the path of JAX's default devices."""
    check_inputs(inputs, "solve_inputs")
    auto, plan = auto_point or auto_normal, plan_for(plan)
    return run_row(stages(auto_point, auto_normal, smoothing, pole, motion, between, packed=plan.packed), (inputs,),
                   fenced=1 if auto else 0, plan=plan if auto else None)


def stages(auto_point: bool, auto_normal: bool, smoothing=0.0, pole: bool = False, motion: Motion | None = None,
           between=(0, 1), packed: bool = False):
    """The case's pipeline, functions of a row's ``CaseInputs`` and the outputs of the stages before
    (``ks_jax.batch.stages.run``): the exchange's own stages (``model.collision.stages``) at a given
    contact; for automatic contact, the input rules, the contact (``model.contact.automatic_stage``)
    and the exchange there (``exchange_at_contact``). ``smoothing``: a Python number or an array. With
    ``motion`` (a ``case.Motion``), the last stage moves the vehicles on from the exchange to rest
    (``to_rest``): the result's ``rest``. ``between``: the first exchange's bodies (``Case.between``). ``packed``:
    the watched motion carries its state packed (``model.interaction.interact``), as an accelerator's path asks."""
    between = tuple(between)
    *first, last = _exchange_stages(auto_point, auto_normal, smoothing, pole, between)
    auto = auto_point or auto_normal

    def exchange_and_rest(inputs, *earlier):
        result = split_by_crush(last(inputs, *earlier), inputs, between)
        if motion is None and between == tuple(range(len(inputs.vehicles))):
            return result  # the case's two bodies, in order: its exchange's results as they are
        states = body_states(inputs)
        if auto:  # every body at the exchange: the pair where automatic contact put it, the others moved freely
            status, found = earlier
            ok = status == OK
            instant = jnp.where(found.found, found.time + found.contact.penetration_time, 0.0)
            at_exchange = [advance(s, instant) for s in states]
            at_exchange[between[0]], at_exchange[between[1]] = found.state1, found.state2
            states = tuple(jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), moved, s)
                           for moved, s in zip(at_exchange, states))
        if motion is not None:
            result = to_rest(inputs, result, states, motion, smoothing, between, packed)
        result = in_body_order(result, between, states)
        if motion is not None and motion.approach:
            result = result._replace(approach=approaches(inputs, body_states(inputs), motion))
        if motion is not None and motion.times:
            result = result._replace(at=states_at(result, body_states(inputs), motion))
        return result

    every = (*first, exchange_and_rest)
    links = () if motion is None else motion.links
    if links:  # a towed vehicle's position and velocity follow its tow's in every row (a sweep or fit of the tow's)
        every = tuple(_following(stage, links) for stage in every)
    return (*every[:-1], blocked(every[-1]) if motion is not None else every[-1])


def _following(stage, links):
    """``stage`` on inputs whose towed vehicles follow their tows (``case.follow_tows``)."""

    def run(inputs, *earlier):
        return stage(follow_tows(inputs, links), *earlier)

    return run


def split_by_crush(result: ExchangeResult, inputs: CaseInputs, between) -> ExchangeResult:
    """``result`` (the first exchange's, its ``vehicles`` its pair) with the EES of its two vehicles shared in
    proportion to their crush energies (``CaseInputs.crush_energy``, docs/model.md "Crush energy") where both have
    one; as it is otherwise (in proportion to the box overlap's crushes, all of it to a vehicle against a fixed
    object). The energy loss's rounding is the exchange's own (``model.results.energy_loss_rounding``)."""
    weights = inputs.crush_energy
    i, j = between
    if not weights or weights[i] is None or weights[j] is None:
        return result
    c = result.contact
    rounding = energy_loss_rounding(c.energy_loss, c.impulse_magnitude, c.closing_velocity, c.separation_velocity)
    ees = ees_pair(c.energy_loss, weights[i], weights[j], inputs.vehicles[i].mass, inputs.vehicles[j].mass, 0.0,
                   rounding)
    return result._replace(vehicles=tuple(v._replace(ees=e) for v, e in zip(result.vehicles, ees)))


def in_body_order(result: ExchangeResult, between, states) -> ExchangeResult:
    """``result`` with ``vehicles`` as one ``VehicleResult`` per body (those of ``inputs.vehicles``, whose ``states``
    at the first exchange are given): the first exchange's pair's own results (``between``: its vehicle 1, then its
    vehicle 2), and for every other body the results of an exchange it took no part in: no delta-V, its velocity
    then as its velocity after, no crush, and its directions (PDOF, course) undefined where they have none
    (``case.defined_output``). A row whose exchange is invalid has NaN in them too."""
    if tuple(between) == tuple(range(len(states))):
        return result
    valid = result.contact.status < INVALID_NONFINITE
    out = []
    for b, state in enumerate(states):
        if b in between:
            out.append(result.vehicles[between.index(b)])
            continue
        like = result.vehicles[0]
        out.append(mask_invalid(_bystander(state, like), valid))
    return result._replace(vehicles=tuple(out))


def _bystander(state, like: VehicleResult) -> VehicleResult:
    """The results of an exchange a body took no part in, from its ``state`` then."""
    v, w = state.velocity, state.angular_velocity
    zero = jnp.zeros_like(v[0])
    speed = la.safe_norm(v)
    course = la.degrees_0_360(la.safe_atan2(v[1], v[0]))
    return VehicleResult(jnp.zeros_like(v), zero, jnp.zeros_like(v), zero, v, speed, course, w, w[2], zero,
                         jnp.full_like(like.pdof_clock, 12), zero, jnp.full_like(zero, jnp.nan))


def _exchange_stages(auto_point, auto_normal, smoothing, pole, between):
    if auto_point or auto_normal:
        def rules(inputs):
            return input_status(*to_pytrees(inputs, between))

        def contact(inputs, status):
            return automatic_stage(*to_pytrees(inputs, between), inputs.contact.normal_pitch, status,
                                   auto_point=auto_point, auto_normal=auto_normal, pole=pole)

        def exchange(inputs, status, auto):
            return with_speed_status(inputs, exchange_at_contact(*to_pytrees(inputs, between), status, auto,
                                                                 smoothing))

        return rules, contact, exchange
    prepare, impulse, results = collision.stages(smoothing)

    def prepared(inputs):
        p = prepare(*to_pytrees(inputs, between))
        return p._replace(status=speed_status(inputs, p.status))

    def found(inputs, p):
        return impulse(*to_pytrees(inputs, between), p)

    def derived(inputs, p, j):
        return results(*to_pytrees(inputs, between), p, j)

    return prepared, found, derived

