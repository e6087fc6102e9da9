"""The rules a solved row's status follows beyond the exchange's own: a negative speed (reachable by a sweep or
a fit, never by a case file), the motion's inputs, and the words of a case's status."""

from __future__ import annotations

import functools
import operator

import jax.numpy as jnp

from ..case import Case, CaseInputs
from ..case.scale import farthest_out_of_scale
from ..model.motion import MAX_FRICTION as MAX_ROAD_FRICTION
from ..model.results import mask_invalid
from ..model.types import INVALID_NONFINITE, INVALID_OVERFLOW, INVALID_SPEED_1, INVALID_SPEED_2, OK
from ..model.types import ExchangeResult, status_text


def speed_status(inputs: CaseInputs, status):
    """``status`` (() int, the exchange's) with INVALID_SPEED_1 where vehicles[0]'s ``speed`` is negative,
    INVALID_SPEED_2 where another vehicle's is, and ``status`` is not already invalid (the exchange's reasons come
    first).

    A case file refuses a negative speed; a swept, sampled or fitted one can reach it, and ``to_pytrees``
    would turn it into travel backwards along the course. Such a row gets this status and NaN results
    instead (traceable, per row)."""
    s1, others = inputs.vehicles[0].speed, [v.speed < 0 for v in inputs.vehicles[1:]]
    code = jnp.where(s1 < 0, INVALID_SPEED_1, jnp.where(functools.reduce(operator.or_, others), INVALID_SPEED_2, OK))
    return jnp.where((code != OK) & (status < INVALID_NONFINITE), code, status).astype(jnp.asarray(status).dtype)


def with_speed_status(inputs: CaseInputs, result: ExchangeResult) -> ExchangeResult:
    """``result`` of ``inputs`` with ``speed_status`` applied: that status and NaN results where a negative
    speed makes the row invalid."""
    status = speed_status(inputs, result.contact.status)
    result = mask_invalid(result, status == result.contact.status)
    return result._replace(contact=result.contact._replace(status=status))


def motion_rules(road) -> jnp.ndarray:
    """Whether the motion's inputs keep their rules (docs/model.md, "Motion to rest"): road.friction in [0, 10]; per
    vehicle each brake fraction in [0, 1], 0 < cg_to_front_axle < wheelbase, track > 0 and
    0 <= rolling_resistance < road.friction, or 0 on a road of friction 0; all finite. Traced, per row."""
    ok = (road.friction >= 0) & (road.friction <= MAX_ROAD_FRICTION)
    for after in road.vehicles:
        if after is None:
            continue
        b = jnp.asarray(after.brake)
        ok = ok & jnp.all((b >= 0) & (b <= 1)) & (after.cg_to_front_axle > 0) \
            & (after.cg_to_front_axle < after.wheelbase) & jnp.isfinite(after.wheelbase) & (after.track > 0) \
            & jnp.isfinite(after.track) & jnp.isfinite(after.steer) \
            & (after.rolling_resistance >= 0) & ((after.rolling_resistance < road.friction)
                                                 | ((after.rolling_resistance == 0) & (road.friction == 0)))
    return ok


def status_words(case: Case, code) -> str:
    """The status words of a solved case; an overflow also names the input farthest out of scale."""
    text = status_text(code)
    if int(code) == INVALID_SPEED_2 and case.vehicle_count > 2:
        last = case.vehicle_count - 1
        text = text.replace("vehicles[1].speed", f"the speed of each of vehicles[1] to vehicles[{last}]")
    if int(code) == INVALID_OVERFLOW:
        text += f"; the input farthest out of scale: {farthest_out_of_scale(case.inputs)}"
    return text
