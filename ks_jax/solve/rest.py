"""The motion to rest of a solved row: each vehicle carried on from the exchange, every pair of bodies watched for the
exchanges that follow (``model.interaction``); rows whose exchange or motion breaks a rule moved from harmless
stand-ins."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..case import CaseInputs, Motion
from ..model.interaction import Bodies, Watch, interact
from ..model.pairs import pairs_of
from ..model.joint import Hitch, carried
from ..model.approach import Phases, approach, state_at
from ..model.motion import MAX_FRICTION, Chassis, Planar, Wheels, body
from ..model.results import mask_invalid
from ..model.types import INVALID_MOTION, INVALID_NONFINITE, ExchangeResult, Vehicle
from .rules import motion_rules


def to_rest(inputs: CaseInputs, result: ExchangeResult, states, motion: Motion, smoothing=0.0,
            between=(0, 1), packed: bool = False) -> ExchangeResult:
    """``result`` (the first exchange's, between the bodies ``between``) with ``rest`` and ``interactions``: the
    vehicles' motion from their states at the exchange (``states``, a ``model.types.State`` per body of
    ``inputs.vehicles``), the pair's with their velocities and yaw rates after it, every pair of bodies watched for
    later exchanges (``model.interaction.interact``, its loop's state ``packed`` or not) until every vehicle rests.

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
    moving = [k for k, after in enumerate(road.vehicles) if after is not None]  # the vehicles, then the objects
    order = moving + [k for k, after in enumerate(road.vehicles) if after is None]
    vehicles, z, bodies, starts, fixed = [], [], [], [], []
    for k in order:
        v, state, after = inputs.vehicles[k], states[k], road.vehicles[k]
        mass = jnp.where(ok, v.mass, 1.0) if after is not None else jnp.asarray(v.mass, friction.dtype)
        vehicles.append(Vehicle(mass, jnp.where(ok, v.inertia, jnp.eye(3)), *(
            jnp.where(ok, getattr(v, f), d) for f, d in zip(Vehicle._fields[2:], (4.5, 1.8, 1.4, 2.25, 0.55)))))
        z.append(jnp.where(ok, state.position[2], 0.55))
        yaw = jnp.where(ok, state.yaw, 0.0)
        if after is None:
            fixed.append(Planar(jnp.where(ok, state.position[:2], 0.0), yaw, jnp.zeros(2, yaw.dtype),
                                jnp.zeros_like(yaw)))
            continue
        if k in between:
            vr = result.vehicles[between.index(k)]
            velocity, yaw_rate = vr.velocity_after[:2], vr.angular_velocity_after[2]
        else:  # a body the first exchange left as it was
            velocity, yaw_rate = state.velocity[:2], state.angular_velocity[2]
        after = jax.tree_util.tree_map(lambda x, d: jnp.where(ok, x, d), after, _stand_in(after))
        starts.append(Planar(jnp.where(ok, state.position[:2], 0.0), yaw, jnp.where(ok, velocity, 0.0),
                             jnp.where(ok, yaw_rate, 0.0)))
        chassis = Chassis(after.wheelbase, after.track, after.cg_to_front_axle)
        wheels = Wheels(after.brake, after.steer, after.rolling_resistance)
        bodies.append(body(vehicles[-1].mass, jnp.where(ok, jnp.asarray(v.inertia)[2, 2], 1.0),
                           vehicles[-1].cg_height, chassis, wheels, friction, motion.time_step))
    hitches = [Hitch(*(jnp.where(ok, jnp.asarray(x, friction.dtype), d) for x, d in zip(h, (0.0, 0.0, jnp.inf))))
               for h in inputs.hitches]
    for (towed, tow, kind), hitch in zip(motion.links, hitches):
        if kind == "fifth_wheel":  # the towed vehicle's front carried by its tow (the vehicles come first in order)
            bodies[tow], bodies[towed] = carried(bodies[tow], bodies[towed], hitch)
    links = tuple((towed, tow) for towed, tow, _ in motion.links)
    stack = lambda parts: jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *parts)  # noqa: E731
    no_fixed = Planar(jnp.zeros((0, 2)), jnp.zeros(0), jnp.zeros((0, 2)), jnp.zeros(0))
    everything = Bodies(stack(vehicles), jnp.stack(z), stack(bodies), stack(fixed) if fixed else no_fixed)
    pairs = pairs_of(len(moving), len(order) - len(moving), links)
    later = inputs.interaction if inputs.interaction is not None else inputs.contact
    own = {pairs.index(tuple(sorted((order.index(i), order.index(j))))): values
           for (i, j), values in zip(motion.pairs, inputs.pairs)}  # pairs with values of their own

    def per_pair(field):
        return jnp.stack([jnp.asarray(getattr(own[p] if p in own else later, field), friction.dtype)
                          for p in range(len(pairs))])

    watch = Watch(*(jnp.where(ok, per_pair(f), 0.0) for f in ("restitution", "friction", "penetration_time")),
                  jnp.asarray(motion.approach_tolerance))
    first = (order.index(between[0]), order.index(between[1]))
    at = None
    if motion.times:  # the times at which each vehicle's state is asked for (the motion's are those after 0)
        at = jnp.stack([times_of(motion, k, friction.dtype) for k in range(len(moving))])
    out = interact(everything, stack(starts), result, first, watch, max_exchanges=motion.max_exchanges,
                   dt=motion.time_step, time_limit=motion.time_limit, poles=tuple(order.index(k) for k in motion.poles),
                   smoothing=smoothing, path=motion.path, reverse=motion.reverse,
                   hitches=stack(hitches) if hitches else None, links=links, at=at, packed=packed)
    rest = [None] * len(order)
    for m, k in enumerate(moving):
        rest[k] = mask_invalid(out.rest[m], ok)
    interactions = mask_invalid(out._replace(rest=()), ok)
    return result._replace(rest=tuple(rest), interactions=interactions)


def times_of(motion: Motion, k: int, dtype):
    """(T,) the times of vehicle ``k`` (``motion.times``), padded with NaN to the case's most, or None for none."""
    if not motion.times:
        return None
    count = max(len(t) for t in motion.times)
    times = motion.times[k] if k < len(motion.times) else ()
    return jnp.asarray(list(times) + [jnp.nan] * (count - len(times)), dtype)


def states_at(result: ExchangeResult, states, motion: Motion) -> tuple:
    """Each vehicle's state at its times (``motion.times``): before the impact from its approach (``result.approach``;
    at the impact, 0, its state there, ``states``), after it from the watched motion (``result.interactions.at``): a
    ``StateAt`` with its ``time``, or None for a body without times. A time before the impact of a vehicle without an
    approach has NaN."""
    out = []
    for k, times in enumerate(motion.times):
        if not times:
            out.append(None)
            continue
        s = states[k]
        t = times_of(motion, k, s.yaw.dtype)
        impact = jnp.concatenate([s.position[:2], s.yaw[None], s.velocity[:2], s.angular_velocity[2:], jnp.zeros(1)])
        approach_k = None if result.approach is None else result.approach[k]
        before = (_rows(approach_k.at) if approach_k is not None
                  else jnp.where((t == 0)[:, None], impact[None], jnp.nan))
        after = jax.tree_util.tree_map(lambda x: x[k], result.interactions.at)
        rows = jnp.where((t > 0)[:, None], _rows(after), before)[:len(times)]
        out.append(state_at(rows)._replace(time=t[:len(times)]))
    return tuple(out)


def _rows(state) -> jnp.ndarray:
    """(T, 7) x, y, yaw rad, vx, vy, yaw rate, path of a ``StateAt``."""
    return jnp.concatenate([state.position, jnp.radians(state.yaw)[:, None], state.velocity,
                            state.yaw_rate[:, None], state.distance[:, None]], axis=1)


def _stand_in(after):
    """A harmless vehicle's wheels (a row that breaks a rule moves on these, at rest)."""
    like = lambda x, v: jnp.full_like(jnp.asarray(x, jnp.result_type(float)), v)  # noqa: E731
    return after._replace(wheelbase=like(after.wheelbase, 2.8), track=like(after.track, 1.6),
                          cg_to_front_axle=like(after.cg_to_front_axle, 1.2), brake=like(after.brake, 0.0),
                          steer=like(after.steer, 0.0), rolling_resistance=like(after.rolling_resistance, 0.015))


def approaches(inputs: CaseInputs, states, motion: Motion) -> tuple:
    """Each body's approach (``model.approach``), worked back from its state in the case (``states``, a
    ``model.types.State`` per body: the state at the impact), or None for a body without one. A row whose approach
    breaks a rule (a swept or fitted value can: a negative length, a friction outside [0, 10], a brake fraction
    outside [0, 1], a non-finite value) has NaN in it, computed from harmless stand-ins."""
    out = []
    for k, (kinds, phases) in enumerate(zip(motion.approach, inputs.approach)):
        if not kinds:
            out.append(None)
            continue
        v, after, state = inputs.vehicles[k], inputs.road.vehicles[k], states[k]
        ok = _approach_rules(phases) & motion_rules(inputs.road)
        safe = jax.tree_util.tree_map(lambda x, d: jnp.where(ok, x, d), phases, _phase_stand_in(phases))
        chassis = Chassis(*(jnp.where(ok, x, d) for x, d in zip((after.wheelbase, after.track, after.cg_to_front_axle),
                                                                 (2.8, 1.6, 1.2))))
        impact = Planar(jnp.where(ok, state.position[:2], 0.0), jnp.where(ok, state.yaw, 0.0),
                        jnp.where(ok, state.velocity[:2], 0.0), jnp.where(ok, state.angular_velocity[2], 0.0))
        mass, izz = jnp.where(ok, v.mass, 1.0), jnp.where(ok, jnp.asarray(v.inertia)[2, 2], 1.0)
        found = approach(mass, izz, jnp.where(ok, v.cg_height, 0.5), chassis,
                         Phases(Wheels(safe.brake, safe.steer, safe.rolling_resistance), safe.friction, safe.length),
                         kinds, impact, path=motion.path, at=times_of(motion, k, impact.yaw.dtype))
        out.append(mask_invalid(found, ok))
    return tuple(out)


def _approach_rules(phases) -> jnp.ndarray:
    """Every phase's values within their rules (docs/model.md, "The approach")."""
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(jnp.asarray(x))) for x in phases]))
    brake = jnp.asarray(phases.brake)
    friction = jnp.asarray(phases.friction)
    return (finite & jnp.all((brake >= 0) & (brake <= 1)) & jnp.all(jnp.asarray(phases.length) >= 0)
            & jnp.all((friction >= 0) & (friction <= MAX_FRICTION))
            & jnp.all(jnp.asarray(phases.rolling_resistance) >= 0))


def _phase_stand_in(phases):
    """Harmless phases of the same shapes: 1 s of free rolling on a road of friction 0.7."""
    like = lambda x, v: jnp.full_like(jnp.asarray(x, jnp.result_type(float)), v)  # noqa: E731
    return phases._replace(brake=like(phases.brake, 0.0), steer=like(phases.steer, 0.0),
                           rolling_resistance=like(phases.rolling_resistance, 0.015),
                           friction=like(phases.friction, 0.7), length=like(phases.length, 1.0))
