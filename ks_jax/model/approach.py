"""Before the impact: a vehicle's approach, worked back from its state at the impact (docs/model.md, "The approach").

The approach is a list of phases, earliest first, the last ending at the impact; in each, the wheels run as in the
motion to rest (``model.motion``: free, locked, or braked by a fraction, the front ones steered), on a road of the
phase's friction, for a given duration or over a given distance of the CG's path (a skid mark). From the impact
state, each phase is worked back step by step: the state one step earlier is the one from which the motion's own
step (``motion.step_function()``) arrives at the later state. That inverse is found by a fixed-point iteration (the
earlier state moved by what the step misses, ``INVERSE_ITERATIONS`` times: each pass shrinks the miss by about the
step times the forces' rate of change with the velocity, a few thousandths), so that running the motion forward from
the approach's start returns the impact state.

A phase runs ``PHASE_STEPS`` steps (static): of its duration over that number, or, for a distance, each step as long
as the distance over that number along the CG's path (its time from the step's mean speed). A locked straight skid
is then the closed form: speed sqrt(v^2 + 2 mu g d) at its start, time (v_start - v) / (mu g) before the impact.

Everything here is pure and unbatched, of static shapes (the phases' number and kinds), and works under ``jax.jit``,
``jax.vmap`` and differentiation in both modes.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import linalg as la
from . import motion

PHASE_STEPS = 200  # steps per phase
INVERSE_ITERATIONS = 3  # fixed-point passes per step


class Phases(NamedTuple):
    """A vehicle's approach phases, stacked (P, ...), earliest first: ``wheels`` (a ``motion.Wheels`` of (P, ...)
    leaves), ``friction`` (P,) the road's, ``length`` (P,): s for a phase by duration, m for one by distance (which
    each is, is the static ``kinds``)."""

    wheels: motion.Wheels
    friction: jnp.ndarray
    length: jnp.ndarray


class ApproachResult(NamedTuple):
    """A vehicle's state at the start of each approach phase (P, ...), earliest first: ``speed`` m/s, ``time`` s
    from the impact (<= 0), ``position`` (P, 2) m of the CG, ``yaw`` deg in [0, 360) (as ``rest_yaw``), ``distance``
    m (the CG's path from there to the impact), ``velocity`` (P, 2) m/s, ``yaw_rate`` rad/s; ``path``: None, or
    (P * PHASE_STEPS + 1, 4) time s, x m, y m, yaw rad from the approach's start to the impact."""

    speed: jnp.ndarray
    time: jnp.ndarray
    position: jnp.ndarray
    yaw: jnp.ndarray
    distance: jnp.ndarray
    velocity: jnp.ndarray
    yaw_rate: jnp.ndarray
    path: jnp.ndarray | None = None
    at: StateAt | None = None


class StateAt(NamedTuple):
    """The vehicle's state at given times (T, ...) before the impact (``approach(at=...)``), each interpolated within
    its step: ``speed`` m/s, ``position`` (T, 2) m, ``yaw`` deg in [0, 360), ``velocity`` (T, 2) m/s, ``yaw_rate``
    rad/s, ``distance`` m (the CG's path from there to the impact). A time before the approach's first phase is
    reached by that phase run further back; a time after the impact is not the approach's (NaN)."""

    speed: jnp.ndarray
    position: jnp.ndarray
    yaw: jnp.ndarray
    velocity: jnp.ndarray
    yaw_rate: jnp.ndarray
    distance: jnp.ndarray
    time: jnp.ndarray | None = None  # (T,) s from the impact, where a case's result carries them


def _pack(p: motion.Planar):
    return jnp.concatenate([p.position, p.yaw[None], p.velocity, p.yaw_rate[None]])


def _unpack(x) -> motion.Planar:
    return motion.Planar(x[:2], x[2], x[3:5], x[5])


def _step_back(b: motion.Body, later: motion.Planar, accel, size, by_distance: bool, before: motion.Body | None = None):
    """The state one step before ``later`` (and that step's duration and the CG's path over it, and its
    acceleration): the state from which the motion's step of ``b`` arrives at ``later`` (the module's docstring).
    ``size``: the step's duration (s), or with ``by_distance`` its length along the CG's path (m). The step's load
    transfer is that of the acceleration at the earlier state, of the wheels of the step before it: ``before``, the
    earlier phase's, for the first step of a phase, else ``b``'s."""
    target = _pack(later)

    def forward(earlier, accel):
        if by_distance:  # the step's time from its mean speed: the chord of the step is ``size``
            mean = la.safe_norm(0.5 * (earlier.velocity + later.velocity))
            dt = size / jnp.maximum(mean, 1e-9)
        else:
            dt = size
        carry = motion.Carry(earlier, accel, jnp.zeros_like(dt), jnp.zeros_like(dt), jnp.ones_like(dt))
        return motion.step_function()(b, carry, dt), dt

    def improve(_, xa):  # one pass: the earlier state moved by what the step misses (a loop: one copy of the step)
        x, accel = xa
        reached, dt = forward(_unpack(x), accel)
        accel = reached.accel  # the load transfer of the forces at the earlier state
        if before is not None:
            accel = motion.step_function()(before, motion.Carry(_unpack(x), accel, dt, dt, jnp.ones_like(dt)), dt).accel
        return x + (target - _pack(reached.state)), accel

    x, accel = jax.lax.fori_loop(0, INVERSE_ITERATIONS, improve, (target, accel))
    reached, dt = forward(_unpack(x), accel)
    return _unpack(x), dt, reached.distance, reached.accel


def _catch(at, found, values, later, earlier, t, dt, d, travelled):
    """``found`` (T,) and ``values`` (T, 7) with the times ``at`` (T,) that the step from ``earlier`` (at t - dt, the
    CG's path d + travelled from the impact) to ``later`` (at t, d) spans: the state there, interpolated."""
    inside = (at >= t - dt) & (at <= t) & ~found
    w = la.safe_div(at - (t - dt), dt, 1.0)[:, None]  # 0 at the earlier state, 1 at the later
    a = jnp.concatenate([_pack(earlier), (d + travelled)[None]])
    b = jnp.concatenate([_pack(later), d[None]])
    return found | inside, jnp.where(inside[:, None], a + w * (b - a), values)


def approach(mass, izz, cg_height, chassis: motion.Chassis, phases: Phases, kinds, impact: motion.Planar, *,
             path: bool = False, at=None) -> ApproachResult:
    """The approach (``ApproachResult``) that ends at ``impact`` (a ``motion.Planar``: the vehicle's state at the
    impact). ``kinds`` (static): per phase "duration" or "distance"; ``path`` (static): keep every step's state;
    ``at``: None, or times (T,) s from the impact (<= 0) at which the result's ``at`` gives the state (``StateAt``):
    one beyond the approach's start is reached by its first phase run further back."""
    count = len(kinds)
    state, accel = impact, jnp.zeros_like(impact.velocity)
    time = jnp.zeros_like(impact.yaw)
    distance = jnp.zeros_like(impact.yaw)
    starts, samples = [], []
    at = None if at is None else jnp.asarray(at, impact.yaw.dtype)
    caught = None if at is None else (jnp.zeros(at.shape, bool), jnp.full(at.shape + (7,), jnp.nan, at.dtype))

    def body(k):
        wheels = jax.tree_util.tree_map(lambda x: x[k], phases.wheels)
        return motion.body(mass, izz, cg_height, chassis, wheels, phases.friction[k], motion.TIME_STEP)

    def one(c, _, b, size, by_distance, before=None):
        s, a, t, d, got = c
        earlier, dt, travelled, a = _step_back(b, _unpack(s), a, size, by_distance, before)
        if got is not None:
            got = _catch(at, *got, _unpack(s), earlier, t, dt, d, travelled)
        c = (_pack(earlier), a, t - dt, d + travelled, got)
        return c, jnp.stack([c[2], earlier.position[0], earlier.position[1], earlier.yaw])

    for k in reversed(range(count)):
        b = body(k)
        step = dict(b=b, size=phases.length[k] / PHASE_STEPS, by_distance=kinds[k] == "distance")
        carry, sampled = jax.lax.scan(lambda c, x: one(c, x, **step), (_pack(state), accel, time, distance, caught),
                                      None, length=PHASE_STEPS - 1)
        # the phase's first step: its load transfer is that of the phase before's wheels
        (packed, accel, time, distance, caught), first = one(carry, None, **step, before=body(k - 1) if k else None)
        sampled = jnp.concatenate([sampled, first[None]])
        state = _unpack(packed)
        yaw = la.degrees_0_360(la.safe_atan2(*la.sincos(state.yaw)))
        starts.append((la.safe_norm(state.velocity), time, state.position, yaw, distance, state.velocity,
                       state.yaw_rate))
        samples.append(sampled[::-1])
    starts = starts[::-1]
    stacked = [jnp.stack([s[f] for s in starts]) for f in range(7)]
    kept = None
    if path:
        end = jnp.stack([jnp.zeros_like(impact.yaw), impact.position[0], impact.position[1], impact.yaw])
        kept = jnp.concatenate([*samples[::-1], end[None]], axis=0)
    found = None
    if at is not None:  # the times before the approach's start: its first phase run further back, by duration
        reach = jnp.maximum(jnp.max(time - at), 0.0) * (1.0 + 1e-9)  # a hair further: the earliest time is inside
        further = dict(b=body(0), size=reach / PHASE_STEPS, by_distance=False)
        (_, _, _, _, (_, values)), _ = jax.lax.scan(lambda c, x: one(c, x, **further),
                                                    (_pack(state), accel, time, distance, caught), None,
                                                    length=PHASE_STEPS)
        found = state_at(values)
    return ApproachResult(*stacked, kept, found)


def state_at(values) -> StateAt:
    """A ``StateAt`` from the states (..., 7): x, y, yaw rad, vx, vy, yaw rate, path."""
    yaw, velocity = values[..., 2], values[..., 3:5]
    return StateAt(la.safe_norm(velocity), values[..., :2], la.degrees_0_360(la.safe_atan2(*la.sincos(yaw))),
                   velocity, values[..., 5], values[..., 6])
