"""Contact interactions (docs/model.md, "Contact interactions"): the bodies' motion on from the first exchange, every
pair of bodies watched at every step, and the KS exchanges that follow.

The bodies are V vehicles (they move on the road, ``model.motion``) and F fixed objects (infinite mass, at rest),
given stacked (``Bodies``); the first exchange, between the pair the case names, has already been computed
(``model.collision``, ``model.contact``). From its instant on, at every step of the motion:

1. every vehicle takes one step of ``model.motion`` (the same step as the motion to rest of one vehicle, so that
   a case whose bodies never meet again moves exactly as each vehicle alone would);
2. for every pair of bodies (``pairs``: each pair of vehicles, and each vehicle with each fixed object) whose
   footprints overlap: the centroid P and normal n of the overlap as automatic contact finds them at that instant
   (``contact.contact_geometry``; a pole's disc by ``contact.disc_contact``), and u_n, the relative velocity at P
   along n. Where u_n < -tolerance (approaching) and the pair is not engaged yet, it becomes engaged: at the
   instant its footprints first touched (interpolated within the step) where they did not overlap before the
   step, else now;
3. an engaged pair whose penetration time has run out, and whose footprints still overlap, exchanges a KS impulse
   (``collision.exchange``) at the state then, with its restitution and friction (``Watch``); one exchange per step
   (the pair engaged first). A pair that parts before is no longer engaged. After an exchange the pair is engaged
   again only once u_n at its P turns approaching again. The exchange's impulse changes both bodies' velocities
   and yaw rates (the planar part: vertical motion, pitch and roll are dropped, as in the motion to rest); a
   vehicle that was at rest moves again;
4. exchanges happen at the steps' instants: a time is known to one step (``dt``).

A contact interaction is a maximal interval in which a pair's footprints overlap; its index is given at its first
exchange (interaction 0 is the first exchange's). Exchanges are kept in ``max_exchanges`` slots (slot 0 the first
exchange); a pair due for an exchange when every slot is taken sets ``exhausted``. The loop stops when every
vehicle is at rest and no pair is engaged, or at the time limit.

Everything here is pure and unbatched, of static shapes (V, F, the pairs and the slots), and works under
``jax.jit``, ``jax.vmap`` and forward-mode differentiation (``jax.jvp``, ``jax.jacfwd``), which is exact where the
sequence of exchanges does not change; reverse mode with ``reverse=True`` (every step runs, ``motion.drive``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import linalg as la
from . import motion
from .collision import exchange
from .results import pdof_degrees
from .contact import contact_geometry, disc_gap, footprint, separation
from .contact.geometry import length_tolerance, vertical_middle
from .contact.pole import disc_contact
from .types import OK, Contact, ExchangeResult, State, Vehicle

APPROACH_TOLERANCE = 0.05  # m/s: a pair is approaching where u_n is below minus this
MAX_EXCHANGES = 16  # exchanges per case at most, by default (the first one included)


class Bodies(NamedTuple):
    """The bodies of a case, stacked: ``vehicle`` (a ``Vehicle`` of (N, ...) leaves: the V vehicles, then the F fixed
    objects with mass inf), ``z`` (N,) m, each CG's height at the first exchange; ``motion``: a ``motion.Body`` of
    (V, ...) leaves, the vehicles' integration constants; ``fixed``: a ``motion.Planar`` of (F, ...) leaves, the fixed
    objects' positions and yaws (velocities 0)."""

    vehicle: Vehicle
    z: jnp.ndarray
    motion: motion.Body
    fixed: motion.Planar


class Watch(NamedTuple):
    """The exchanges after the first, per pair (P,): ``restitution``, ``friction``, ``penetration_time`` s; and the
    approach ``tolerance`` () m/s."""

    restitution: jnp.ndarray
    friction: jnp.ndarray
    penetration_time: jnp.ndarray
    tolerance: jnp.ndarray


class Interactions(NamedTuple):
    """The exchanges of a case and what they did (docs/model.md, "Contact interactions").

    ``exchanges``: an ``ExchangeResult`` of (K, ...) leaves (K = ``max_exchanges``; ``rest`` None): slot 0 the first
    exchange, then each later one in time order; slots from ``count`` on are unused (zeros). ``time`` (K,) s from the
    first exchange; ``between`` (K, 2) int32, the bodies' indices (vehicles first, then fixed objects; the first is
    the exchange's vehicle 1); ``interaction`` (K,) int32; ``count`` () int32, the slots used.
    Per vehicle (V, ...): ``delta_v_cumulative`` (V, 3) m/s, over its first interaction, the velocity just after its
    last exchange minus the velocity just before its first (tyre forces between included), zeros for a vehicle in
    none; ``delta_v_impulses`` (V, 3) m/s, the sum of that interaction's impulses on it over its mass;
    ``first_interaction`` (V,) int32, -1 for none; ``delta_v_cumulative_pdof`` (V,) deg, the principal direction of
    ``delta_v_cumulative`` in the vehicle's frame at the first exchange of that interaction (SAE J224, as ``pdof``).
    ``energy_loss_total`` () J over every exchange; ``exhausted`` () bool, a pair was due for an exchange when every
    slot was taken; ``overlapping`` (P,) bool, each pair's footprints overlap at the end; ``rest``: a tuple of V
    ``motion.RestResult``, each vehicle's motion from the first exchange."""

    exchanges: ExchangeResult
    time: jnp.ndarray
    between: jnp.ndarray
    interaction: jnp.ndarray
    count: jnp.ndarray
    delta_v_cumulative: jnp.ndarray
    delta_v_impulses: jnp.ndarray
    first_interaction: jnp.ndarray
    delta_v_cumulative_pdof: jnp.ndarray
    energy_loss_total: jnp.ndarray
    exhausted: jnp.ndarray
    overlapping: jnp.ndarray
    rest: tuple


class _Loop(NamedTuple):
    carry: motion.Carry  # (V, ...) the vehicles' integration
    time: jnp.ndarray  # () s from the first exchange
    gap: jnp.ndarray  # (P,) m, each pair's separation at the last step (< 0 overlapping)
    engaged: jnp.ndarray  # (P,) s, when the pair was engaged; inf where it is not
    current: jnp.ndarray  # (P,) int32, the interaction of the pair's present overlap; -1 for none yet
    interactions: jnp.ndarray  # () int32, interactions so far
    slots: ExchangeResult  # (K, ...) the exchanges
    slot_time: jnp.ndarray
    slot_between: jnp.ndarray
    slot_interaction: jnp.ndarray
    count: jnp.ndarray
    first_interaction: jnp.ndarray  # (V,)
    before: jnp.ndarray  # (V, 3) velocity before the first exchange of the first interaction
    after: jnp.ndarray  # (V, 3) velocity after its last
    impulses: jnp.ndarray  # (V, 3) its impulses over the mass
    heading: jnp.ndarray  # (V,) rad, the yaw at the first exchange of the first interaction
    exhausted: jnp.ndarray


def pairs_of(vehicles: int, fixed: int):
    """The pairs watched (static): every pair of vehicles (i < j), then every vehicle with every fixed object."""
    n = vehicles + fixed
    return tuple((i, j) for i in range(vehicles) for j in range(i + 1, n))


def _state3(position, yaw, velocity, yaw_rate, z):
    zero = jnp.zeros_like(yaw)
    return State(jnp.stack([position[0], position[1], z]), jnp.stack([velocity[0], velocity[1], zero]), yaw, zero,
                 zero, jnp.stack([zero, zero, yaw_rate]))


def _pick(tree, i):
    return jax.tree_util.tree_map(lambda x: x[i], tree)


def _planes(bodies: Bodies, carry: motion.Carry):
    """Every body's planar state as (N, ...) arrays: the vehicles' from ``carry``, then the fixed objects'."""
    f = bodies.fixed
    s = carry.state
    return (jnp.concatenate([s.position, f.position]), jnp.concatenate([s.yaw, f.yaw]),
            jnp.concatenate([s.velocity, f.velocity]), jnp.concatenate([s.yaw_rate, f.yaw_rate]))


def _pair_contact(v1, s1, v2, s2, pole):
    """(separation () m, < 0 overlapping; centroid (3,) m; normal (3,), from body 2 into body 1) of two bodies as they
    stand, worked about their CGs' midpoint (as automatic contact does); ``pole`` (static): body 2 is a pole's
    disc."""
    origin = (0.5 * (s1.position + s2.position)).at[2].set(0.0)
    n1, n2 = (s._replace(position=s.position - origin) for s in (s1, s2))
    far = la.safe_norm(origin)
    if pole:
        gap = disc_gap(v1, n1, v2, n2, 0.0)
        tol = length_tolerance(v1, v2, origin.dtype, far)
        xy, n, *_ = disc_contact(v1, n1, n2.position[:2], 0.5 * v2.width, footprint(v1, n1.position[:2], n1.yaw),
                                 tol, n1, n2.position[:2])
        point = jnp.stack([xy[0], xy[1], vertical_middle(v1, n1, v2, n2)])
        normal = jnp.stack([n[0], n[1], jnp.zeros_like(n[0])])
    else:
        gap = separation(v1, n1, v2, n2, 0.0)
        geo = contact_geometry(v1, n1, v2, n2, far)
        point, normal = geo.point, geo.normal
    return gap, point + origin, normal


def _closing(point, normal, s1, s2):
    """u_n: the relative velocity of body 1 over body 2 at ``point`` along ``normal``."""
    u = (s1.velocity + la.cross(s1.angular_velocity, point - s1.position)) - (
        s2.velocity + la.cross(s2.angular_velocity, point - s2.position))
    return normal @ u


def _watch_pairs(bodies, states, pairs, poles):
    """(gap, point, normal, u_n) of every pair, (P,) (P, 3) (P, 3) (P,): the pairs against a box vmapped together,
    those against a pole together."""
    out = [None] * len(pairs)
    for pole in (False, True):
        idx = [k for k, (_, j) in enumerate(pairs) if (j in poles) == pole]
        if not idx:
            continue
        i = jnp.array([pairs[k][0] for k in idx])
        j = jnp.array([pairs[k][1] for k in idx])
        v1, v2, s1, s2 = _pick(bodies.vehicle, i), _pick(bodies.vehicle, j), _pick(states, i), _pick(states, j)
        gap, point, normal = jax.vmap(lambda a, b, c, d: _pair_contact(a, b, c, d, pole))(v1, s1, v2, s2)
        un = jax.vmap(_closing)(point, normal, s1, s2)
        for m, k in enumerate(idx):
            out[k] = (gap[m], point[m], normal[m], un[m])
    return tuple(jnp.stack(x) for x in zip(*out))


def _record(loop: _Loop, result: ExchangeResult, when, pair, interaction, do):
    """``loop`` with ``result`` written into the next slot where ``do``."""
    k = jnp.minimum(loop.count, loop.slot_time.shape[0] - 1)

    def put(buf, x):
        return buf.at[k].set(jnp.where(do, x, buf[k]))

    slots = jax.tree_util.tree_map(put, loop.slots, result._replace(rest=None))
    return loop._replace(slots=slots, slot_time=put(loop.slot_time, when),
                         slot_between=put(loop.slot_between, pair), slot_interaction=put(loop.slot_interaction,
                                                                                          interaction),
                         count=loop.count + do.astype(loop.count.dtype))


def _cumulate(loop: _Loop, result: ExchangeResult, pair, yaws, interaction, do, vehicles: int):
    """The vehicles' first-interaction bookkeeping after the exchange ``result`` (between ``pair``, whose yaws were
    ``yaws``, of ``interaction``) where ``do``."""
    first, before, after, impulses = loop.first_interaction, loop.before, loop.after, loop.impulses
    heading = loop.heading
    for side in range(2):
        b = pair[side]
        is_vehicle = b < vehicles
        b = jnp.minimum(b, vehicles - 1)
        vr = result.vehicles[side]
        starts = do & is_vehicle & (first[b] < 0)
        adds = do & is_vehicle & ((first[b] < 0) | (first[b] == interaction))
        before = before.at[b].set(jnp.where(starts, vr.velocity_after - vr.delta_v, before[b]))
        heading = heading.at[b].set(jnp.where(starts, yaws[side], heading[b]))
        after = after.at[b].set(jnp.where(adds, vr.velocity_after, after[b]))
        impulses = impulses.at[b].set(jnp.where(adds, impulses[b] + vr.delta_v, impulses[b]))
        first = first.at[b].set(jnp.where(starts, interaction, first[b]))
    return loop._replace(first_interaction=first, before=before, after=after, impulses=impulses, heading=heading)


def _step(bodies: Bodies, watch: Watch, loop: _Loop, *, pairs, poles, dt, smoothing, advance) -> _Loop:
    """One step of the watched motion (the module's docstring, 1-3)."""
    vehicles = loop.carry.time.shape[0]
    carry = jax.vmap(lambda b, c: advance(b, c, dt))(bodies.motion, loop.carry)
    time = loop.time + dt
    position, yaw, velocity, yaw_rate = _planes(bodies, carry)
    states = jax.vmap(_state3)(position, yaw, velocity, yaw_rate, bodies.z)
    gap, point, normal, un = _watch_pairs(bodies, states, pairs, poles)
    overlap = gap < 0
    # engaged: at the first touch within the step where the footprints did not overlap before it, else now
    touch = time - dt * la.safe_div(-gap, loop.gap - gap, 0.0)
    since = jnp.where(loop.gap >= 0, jnp.clip(touch, time - dt, time), time)
    engaged = jnp.where(overlap, jnp.where(jnp.isinf(loop.engaged) & (un < -watch.tolerance), since, loop.engaged),
                        jnp.inf)
    current = jnp.where(overlap, loop.current, -1)
    due = overlap & (time >= engaged + watch.penetration_time - 1e-9 * dt)
    p = jnp.argmin(jnp.where(due, engaged, jnp.inf))
    fire = due[p]
    slots_left = loop.count < loop.slot_time.shape[0]
    i, j = jnp.asarray(pairs)[p, 0], jnp.asarray(pairs)[p, 1]
    contact = Contact(point[p], normal[p], watch.restitution[p], watch.friction[p], watch.penetration_time[p])
    result = exchange(_pick(bodies.vehicle, i), _pick(states, i), _pick(bodies.vehicle, j), _pick(states, j),
                      contact, smoothing)
    do = fire & slots_left & (result.contact.status == OK)
    new = current[p] < 0
    interaction = jnp.where(new, loop.interactions, current[p])
    loop = loop._replace(exhausted=loop.exhausted | (fire & ~slots_left))
    # due within the step: the exchange at its due instant, the bodies carried on from it with their new velocities
    when = jnp.clip(engaged[p] + watch.penetration_time[p], time - dt, time)
    lag = time - when
    loop = _record(loop, result, when, jnp.stack([i, j]).astype(jnp.int32), interaction, do)
    loop = _cumulate(loop, result, (i, j), (states.yaw[i], states.yaw[j]), interaction, do, vehicles)
    # the impulse's planar part on each vehicle of the pair; a vehicle at rest moves again from now
    s = carry.state
    pos, yaw, vel, rate, moving, clock = s.position, s.yaw, s.velocity, s.yaw_rate, carry.moving, carry.time
    for side, b in enumerate((i, j)):
        hit = do & (b < vehicles)
        b = jnp.minimum(b, vehicles - 1)
        vr = result.vehicles[side]
        new_v, new_r = vr.velocity_after[:2], vr.angular_velocity_after[2]
        pos = pos.at[b].set(jnp.where(hit, pos[b] + lag * (new_v - vel[b]), pos[b]))
        yaw = yaw.at[b].set(jnp.where(hit, yaw[b] + lag * (new_r - rate[b]), yaw[b]))
        vel = vel.at[b].set(jnp.where(hit, new_v, vel[b]))
        rate = rate.at[b].set(jnp.where(hit, new_r, rate[b]))
        clock = clock.at[b].set(jnp.where(hit & (carry.moving[b] < 1.0), time, clock[b]))
        moving = moving.at[b].set(jnp.where(hit, 1.0, moving[b]))
    carry = carry._replace(state=motion.Planar(pos, yaw, vel, rate), moving=moving, time=clock)
    cleared = jnp.arange(len(pairs)) == p
    engaged = jnp.where(cleared & fire, jnp.inf, engaged)
    current = jnp.where(cleared & do & new, interaction, current)
    return loop._replace(carry=carry, time=time, gap=gap, engaged=engaged, current=current,
                         interactions=loop.interactions + (do & new).astype(jnp.int32))


def interact(bodies: Bodies, start: motion.Planar, first: ExchangeResult, first_pair, watch: Watch, *,
             max_exchanges: int = MAX_EXCHANGES, dt: float = motion.TIME_STEP,
             time_limit: float = motion.TIME_LIMIT, poles=(), smoothing=0.0, path: bool = False,
             reverse: bool = False) -> Interactions:
    """The watched motion from the first exchange (``Interactions``).

    ``bodies``: the case's bodies (``Bodies``); ``start``: a ``motion.Planar`` of (V, ...) leaves, each vehicle at the
    first exchange's instant, with its velocity and yaw rate after it; ``first``: the first exchange's result (its
    pair's ``vehicles``); ``first_pair``: its two bodies' indices (static, a vehicle first); ``watch``: the later
    exchanges' settings per pair (``pairs_of`` order). Static: ``max_exchanges`` (slots, the first exchange's
    included), ``dt``, ``time_limit`` s, ``poles`` (indices of the bodies that are poles), ``smoothing`` (of the
    exchanges), ``path`` (each vehicle's rest result keeps its path) and ``reverse`` (``motion.drive``)."""
    vehicles = start.yaw.shape[0]
    fixed = bodies.fixed.yaw.shape[0]
    pairs = pairs_of(vehicles, fixed)
    if tuple(first_pair) not in pairs:
        raise ValueError(f"interact: the first exchange's pair {tuple(first_pair)} is not one of the pairs {pairs}")
    dtype = start.yaw.dtype
    carry = jax.vmap(motion.start_carry)(start)
    position, yaw, velocity, yaw_rate = _planes(bodies, carry)
    states = jax.vmap(_state3)(position, yaw, velocity, yaw_rate, bodies.z)
    gap = _watch_pairs(bodies, states, pairs, tuple(poles))[0]
    k = max_exchanges
    slots = jax.tree_util.tree_map(lambda x: jnp.zeros((k,) + jnp.shape(x), jnp.result_type(x)),
                                   first._replace(rest=None))
    pair0 = jnp.asarray(first_pair, jnp.int32)
    # the first exchange's interaction lasts while its pair's footprints overlap
    current = jnp.full((len(pairs),), -1, jnp.int32).at[pairs.index(tuple(first_pair))].set(0)
    loop = _Loop(carry, jnp.zeros((), dtype), gap, jnp.full((len(pairs),), jnp.inf, dtype), current,
                 jnp.ones((), jnp.int32), slots, jnp.zeros(k, dtype), jnp.zeros((k, 2), jnp.int32),
                 jnp.zeros(k, jnp.int32), jnp.zeros((), jnp.int32), jnp.full((vehicles,), -1, jnp.int32),
                 jnp.zeros((vehicles, 3), dtype), jnp.zeros((vehicles, 3), dtype), jnp.zeros((vehicles, 3), dtype),
                 jnp.zeros(vehicles, dtype), jnp.zeros((), bool))
    exchanged = first.contact.status == OK
    loop = _record(loop, first, jnp.zeros((), dtype), pair0, jnp.zeros((), jnp.int32), jnp.ones((), bool))
    loop = _cumulate(loop, first, pair0, (states.yaw[first_pair[0]], states.yaw[first_pair[1]]),
                     jnp.zeros((), jnp.int32), exchanged, vehicles)
    advance = motion.step_function(reverse and not path)
    step = lambda lp: _step(bodies, watch, lp, pairs=pairs, poles=tuple(poles), dt=dt,  # noqa: E731
                            smoothing=smoothing, advance=advance)
    busy = lambda lp: jnp.any(lp.carry.moving >= 1.0) | jnp.any(~jnp.isinf(lp.engaged))  # noqa: E731
    sample = (lambda lp: jax.vmap(motion.path_sample)(lp.carry)) if path else None
    final, samples = motion.drive(step, loop, motion.steps_for(time_limit, dt), busy, sample=sample,
                                  reverse=reverse)
    rest = tuple(motion.rest_result(_pick(start, v), _pick(final.carry, v),
                                    None if samples is None else samples[:, v]) for v in range(vehicles))
    used = jnp.arange(k) < final.count
    energy = jnp.sum(jnp.where(used, final.slots.contact.energy_loss, 0.0))
    in_one = final.first_interaction >= 0
    cumulative = jnp.where(in_one[:, None], final.after - final.before, 0.0)
    # the cumulative delta-V in the vehicle's frame at its first exchange: the direction the force came from
    sin, cos = la.sincos(final.heading)
    body = jnp.stack([cos * cumulative[:, 0] + sin * cumulative[:, 1], cos * cumulative[:, 1] - sin * cumulative[:, 0],
                      cumulative[:, 2]], axis=-1)
    pdof = jax.vmap(pdof_degrees)(body)
    return Interactions(final.slots, final.slot_time, final.slot_between, final.slot_interaction, final.count,
                        cumulative, final.impulses, final.first_interaction, pdof, energy, final.exhausted,
                        final.gap < 0, rest)
