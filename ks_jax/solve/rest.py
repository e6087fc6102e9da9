"""The motion to rest of a solved row: each vehicle carried on from the exchange (``model.motion.to_rest``), rows
whose exchange or motion breaks a rule moved from harmless stand-ins."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..case import CaseInputs, Motion
from ..model.motion import Chassis, Planar, Wheels
from ..model.motion import to_rest as motion_to_rest
from ..model.results import mask_invalid
from ..model.types import INVALID_MOTION, INVALID_NONFINITE, ExchangeResult
from .rules import motion_rules


def to_rest(inputs: CaseInputs, result: ExchangeResult, states, motion: Motion) -> ExchangeResult:
    """``result`` with ``rest``: each vehicle's motion from its state at the exchange (``states``, the pair of
    ``model.types.State``) with its velocity and yaw rate after it, to rest (``model.motion.to_rest``).

    A row whose exchange is invalid, or whose motion's inputs break their rules (``motion_rules``: a swept or
    fitted value can, a case file cannot), has NaN in every result and, for the latter, status
    INVALID_MOTION. Such rows move from harmless stand-ins (at rest, on a default road), so that their
    gradients stay finite."""
    road = inputs.road
    rules = motion_rules(road)
    status = result.contact.status
    valid = status < INVALID_NONFINITE
    ok = valid & rules
    status = jnp.where(valid & ~rules, jnp.int32(INVALID_MOTION), status).astype(status.dtype)
    result = mask_invalid(result, ~(valid & ~rules))
    result = result._replace(contact=result.contact._replace(status=status))
    friction = jnp.where(ok, road.friction, 0.7)
    rest = []
    for v, after, state, vr in zip(inputs.vehicles, road.vehicles, states, result.vehicles):
        if after is None:  # a fixed object does not move
            rest.append(None)
            continue
        after = jax.tree_util.tree_map(lambda x, d: jnp.where(ok, x, d), after, _stand_in(after))
        start = Planar(jnp.where(ok, state.position[:2], 0.0), jnp.where(ok, state.yaw, 0.0),
                       jnp.where(ok, vr.velocity_after[:2], 0.0), jnp.where(ok, vr.angular_velocity_after[2], 0.0))
        mass, izz = jnp.where(ok, v.mass, 1.0), jnp.where(ok, jnp.asarray(v.inertia)[2, 2], 1.0)
        chassis = Chassis(after.wheelbase, after.track, after.cg_to_front_axle)
        wheels = Wheels(after.brake, after.steer, after.rolling_resistance)
        r = motion_to_rest(mass, izz, jnp.where(ok, v.cg_height, 0.0), chassis, wheels, friction, start,
                           dt=motion.time_step, time_limit=motion.time_limit, path=motion.path, reverse=motion.reverse)
        rest.append(mask_invalid(r, ok))
    return result._replace(rest=tuple(rest))


def _stand_in(after):
    """A harmless vehicle's wheels (a row that breaks a rule moves on these, at rest)."""
    like = lambda x, v: jnp.full_like(jnp.asarray(x, jnp.result_type(float)), v)  # noqa: E731
    return after._replace(wheelbase=like(after.wheelbase, 2.8), track=like(after.track, 1.6),
                          cg_to_front_axle=like(after.cg_to_front_axle, 1.2), brake=like(after.brake, 0.0),
                          steer=like(after.steer, 0.0), rolling_resistance=like(after.rolling_resistance, 0.015))
