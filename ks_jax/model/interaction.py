"""Contact interactions (docs/model.md, "Contact interactions"): the bodies' motion on from the first exchange, every
pair of bodies watched at every step, and the KS exchanges that follow.

The bodies are V vehicles (they move on the road, ``model.motion``) and F fixed objects (infinite mass, at rest),
given stacked (``Bodies``); the first exchange, between the pair the case names, has already been computed
(``model.collision``, ``model.contact``). From its instant on, at every step of the motion:

1. every vehicle takes one step of ``model.motion`` (the same step as the motion to rest of one vehicle, so that
   a case whose bodies never meet again moves exactly as each vehicle alone would);
2. for every pair of bodies (``model.pairs``: each pair of vehicles, and each vehicle with each fixed object) whose
   footprints overlap: the centroid P and normal n of the overlap as automatic contact finds them at that instant
   (``contact.contact_geometry``; a pole's disc by ``contact.disc_contact``), and u_n, the relative velocity at P
   along n. Where u_n < -tolerance (approaching) and the pair is not engaged yet, it becomes engaged: at the
   instant its footprints first touched (interpolated within the step) where they did not overlap before the
   step, else now;
3. an engaged pair whose penetration time has run out, and whose footprints still overlap, exchanges a KS impulse
   (``collision``) at the state then, at its current P and n, with its restitution and friction (``Watch``); the
   pairs due at one step exchange one after another, the pair engaged first first. A pair that parts before is no
   longer engaged. After an exchange the pair is engaged again only once u_n at its P turns approaching again. The
   impulse changes both bodies' velocities and yaw rates (the planar part: vertical motion, pitch and roll are
   dropped, as in the motion to rest); a vehicle that was at rest moves again;
4. an exchange due within a step happens at its due instant (the touch interpolated within the step, plus the
   penetration time): the pair is taken back to it along its motion, the contact point with it, and carried on
   from it with its new velocities, so that the positions, and the separations the next step interpolates its
   touches from, are those of motion that changed at that instant. On a frictionless road, times, impulses and paths
   are those of the exact sequence of exchanges.

Cost: the close look at a pair (its separation, the overlap's centroid and normal) is taken only where the pair's
circles of reach meet and one of its vehicles moves, and for a batch (``jax.vmap``) only at the steps where some row
needs it (``model.pairs``); an exchange's impulse is computed only at the steps where some row has one due, and its
full results (``collision.exchange``: crush, EES, PDOF, ...) once per recorded exchange, after the loop.

A contact interaction is a maximal interval in which a pair's footprints overlap; its index is given at its first
exchange (interaction 0 is the first exchange's). Exchanges are kept in ``max_exchanges`` slots (slot 0 the first
exchange); a pair due for an exchange when every slot is taken sets ``exhausted``. The loop stops when every
vehicle is at rest and no pair is engaged, or at the time limit.

Everything here is pure and unbatched, of static shapes (V, F, the pairs and the slots), and works under
``jax.jit``, ``jax.vmap`` and forward-mode differentiation (``jax.jvp``, ``jax.jacfwd``), which is exact where the
sequence of exchanges does not change; reverse mode with ``reverse=True`` (every step runs, ``motion_loop.drive``).
"""

from __future__ import annotations

import functools
import operator
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from . import joint
from .approach import state_at
from . import linalg as la
from . import motion, motion_loop
from .collision import Prepared, exchange, impulse
from .results import mask_invalid, pdof_degrees
from .packing import Packing
from .pairs import any_row, gaps, material_velocity, pairs_of, watch_gaps, watch_pairs
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
    slot was taken; ``overlapping`` (P,) bool, each pair's footprints overlap at the end, and ``overlap_depth`` (P,)
    m by how much (the least push that would part them, 0 where apart); ``rest``: a tuple of V
    ``motion.RestResult``, each vehicle's motion from the first exchange; ``at``: None, or where ``interact`` was given
    times, each vehicle's state at them (``approach.StateAt`` of (V, T, ...) leaves): interpolated within the step
    that spans the time, the state where the motion ended for a time after its end, NaN for a time not after the
    first exchange."""

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
    overlap_depth: jnp.ndarray
    rest: tuple
    at: Any = None


class _Loop(NamedTuple):
    carry: motion.Carry  # (V, ...) the vehicles' integration
    time: jnp.ndarray  # () s from the first exchange
    step: jnp.ndarray  # () int32, steps so far
    gap: jnp.ndarray  # (P,) m, each pair's separation at the last step (< 0 overlapping)
    point: jnp.ndarray  # (P, 3) m, each pair's centroid at the last step
    normal: jnp.ndarray  # (P, 3) its normal
    engaged: jnp.ndarray  # (P,) s, when the pair was engaged; inf where it is not
    due: jnp.ndarray  # (P,) bool, engaged for the penetration time: an exchange is due
    current: jnp.ndarray  # (P,) int32, the interaction of the pair's present overlap; -1 for none yet
    interactions: jnp.ndarray  # () int32, interactions so far
    slot_states: State  # (K, 2, ...) each exchange's two bodies just before it
    slot_contact: Contact  # (K, ...) its contact
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
    caught: Any = None  # None, or (times (V, T), found (V, T), the states there (V, T, 7)): ``_catch``


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


def _record(loop: _Loop, states: State, contact: Contact, when, pair, interaction, do):
    """``loop`` with an exchange written into the next slot where ``do``: the pair's ``states`` (2, ...) just before
    it, its ``contact``, time, pair and interaction (its results are derived from these after the loop)."""
    k = jnp.minimum(loop.count, loop.slot_time.shape[0] - 1)

    def put(buf, x):
        return buf.at[k].set(jnp.where(do, x, buf[k]))

    return loop._replace(slot_states=jax.tree_util.tree_map(put, loop.slot_states, states),
                         slot_contact=jax.tree_util.tree_map(put, loop.slot_contact, contact),
                         slot_time=put(loop.slot_time, when), slot_between=put(loop.slot_between, pair),
                         slot_interaction=put(loop.slot_interaction, interaction),
                         count=loop.count + do.astype(loop.count.dtype))


def _cumulate(loop: _Loop, before, after, pair, yaws, interaction, do, vehicles: int):
    """The vehicles' first-interaction bookkeeping after an exchange between the bodies ``pair`` (whose velocities
    were ``before`` (n, 3) and are ``after`` (n, 3), whose yaws were ``yaws``), of ``interaction``, where ``do`` (a
    flag, or one per body). The bodies are the exchange's two, and the vehicles a hitch's impulse then moved."""
    first, start, end, impulses = loop.first_interaction, loop.before, loop.after, loop.impulses
    heading = loop.heading
    for side in range(len(pair)):
        b = pair[side]
        do_side = do if jnp.ndim(do) == 0 else do[side]
        is_vehicle = b < vehicles
        b = jnp.minimum(b, vehicles - 1)
        starts = do_side & is_vehicle & (first[b] < 0)
        adds = do_side & is_vehicle & ((first[b] < 0) | (first[b] == interaction))
        start = start.at[b].set(jnp.where(starts, before[side], start[b]))
        heading = heading.at[b].set(jnp.where(starts, yaws[side], heading[b]))
        end = end.at[b].set(jnp.where(adds, after[side], end[b]))
        impulses = impulses.at[b].set(jnp.where(adds, impulses[b] + after[side] - before[side], impulses[b]))
        first = first.at[b].set(jnp.where(starts, interaction, first[b]))
    return loop._replace(first_interaction=first, before=start, after=end, impulses=impulses, heading=heading)


def _impulse(vehicle1, state1, vehicle2, state2, contact, smoothing):
    """The exchange's impulse and what it does to the two bodies, without the rest of its results (those of the
    recorded exchanges are derived after the loop, ``collision.exchange``): (whether an impulse was exchanged, the
    velocities (2, 3) and angular velocities (2, 3) after it)."""
    # the bodies keep the input rules (the first exchange checked them; the watch's settings are checked where a case
    # is read); planar states: pitch and roll 0
    zero = jnp.zeros_like(state1.yaw)
    prepared = Prepared(jnp.zeros((), jnp.int32), (la.trig(state1.yaw, zero, zero), la.trig(state2.yaw, zero, zero)))
    found = impulse(vehicle1, state1, vehicle2, state2, contact, prepared, smoothing)
    j = la.array(found.j)
    a1, a2 = la.from_rows(found.a1), la.from_rows(found.a2)
    r1, r2 = la.array(found.r1), la.array(found.r2)
    v1 = state1.velocity + j / vehicle1.mass
    v2 = state2.velocity - j / vehicle2.mass  # 1 / inf = 0: a fixed object does not move
    w1 = state1.angular_velocity + la.mm(a1, la.cross(r1, j))
    w2 = state2.angular_velocity - la.mm(a2, la.cross(r2, j))
    ok = found.approaching & jnp.all(jnp.isfinite(j))
    return ok, jnp.stack([v1, v2]), jnp.stack([w1, w2])


def _states(bodies: Bodies, carry: motion.Carry):
    """Every body's ``State`` (N, ...) from the vehicles' ``carry`` and the fixed objects."""
    return jax.vmap(_state3)(*_planes(bodies, carry), bodies.z)


def _coupled(bodies: Bodies, carry: motion.Carry, time, hitches, links, since=None) -> motion.Carry:
    """``carry`` with every hitch's impulse given (``joint.couple``), and where ``since`` (the carry before the step)
    is given the hitch points put together again: a vehicle at rest that the joint sets moving moves again from
    ``time``. A hitched vehicle's path then grows by the chord of its step, the joint's correction included (its
    own step and the correction may go opposite ways, and their sum would count both)."""
    if not links:
        return carry
    new = joint.couple(carry.state, bodies.motion.mass, bodies.motion.izz, hitches, links,
                       positions=since is not None)
    woken = (carry.moving < 1.0) & (jnp.any(new.velocity != 0, axis=-1) | (new.yaw_rate != 0))
    distance = carry.distance
    if since is not None:
        hitched = jnp.asarray([any(v in link for link in links) for v in range(carry.distance.shape[0])])
        chord = since.distance + la.safe_norm(new.position - since.state.position)
        distance = jnp.where(hitched, chord, distance)
    return carry._replace(state=new, moving=jnp.where(woken, 1.0, carry.moving),
                          time=jnp.where(woken, time, carry.time), distance=distance)


def _planar3(velocity, like):
    """(3,) the planar ``velocity`` (2,) with the vertical component of ``like`` (3,)."""
    return jnp.concatenate([velocity, like[2:]])


def _row(c: motion.Carry):
    """(V, 7) each vehicle's x, y, yaw, vx, vy, yaw rate and path so far."""
    s = c.state
    return jnp.concatenate([s.position, s.yaw[:, None], s.velocity, s.yaw_rate[:, None], c.distance[:, None]], axis=1)


def _catch(caught, before: motion.Carry, after: motion.Carry, t0, t1):
    """``caught`` (``_Loop.caught``) with the times that the step from ``before`` (at ``t0``) to ``after`` (at ``t1``)
    spans: each vehicle's state there, interpolated. None stays None."""
    if caught is None:
        return None
    times, found, values = caught
    inside = (times > t0) & (times <= t1) & ~found
    w = la.safe_div(times - t0, t1 - t0, 1.0)[..., None]
    a, b = _row(before)[:, None], _row(after)[:, None]
    return times, found | inside, jnp.where(inside[..., None], a + w * (b - a), values)


def _watch_step(bodies: Bodies, watch: Watch, loop: _Loop, *, pairs, poles, dt, advance, hitches=None,
                links=(), packed=False) -> _Loop:
    """One step of the motion, the hitches' joints (``_coupled``), and every pair watched after it (the module's
    docstring, 1-2): which pairs overlap, their centroids and normals, which are engaged and which are due for an
    exchange. ``packed``: the pairs' values go to their close look packed (``pairs.watch_pairs``)."""
    time = loop.time + dt
    carry = jax.vmap(lambda b, c: advance(b, c, dt))(bodies.motion, loop.carry)
    carry = _coupled(bodies, carry, time, hitches, links, since=loop.carry)
    loop = loop._replace(caught=_catch(loop.caught, loop.carry, carry, loop.time, time))
    gap, point, normal, un = watch_pairs(bodies, _states(bodies, carry), carry.moving >= 1.0, pairs, poles, packed)
    overlap = gap < 0
    # engaged: at the first touch within the step where the footprints did not overlap before it, else now
    touch = time - dt * la.safe_div(-gap, loop.gap - gap, 0.0)
    since = jnp.where(loop.gap >= 0, jnp.clip(touch, time - dt, time), time)
    engaged = jnp.where(overlap, jnp.where(jnp.isinf(loop.engaged) & (un < -watch.tolerance), since, loop.engaged),
                        jnp.inf)
    due = overlap & (time >= engaged + watch.penetration_time - 1e-9 * dt)
    return loop._replace(carry=carry, time=time, step=loop.step + 1, gap=gap, engaged=engaged, due=due, point=point,
                         normal=normal, current=jnp.where(overlap, loop.current, -1))


def _fire(bodies: Bodies, watch: Watch, state, packing: Packing, *, pairs, poles, dt, smoothing, hitches=None,
          links=()):
    """The exchange of the due pair engaged first, if any (the module's docstring, 3): recorded, its impulse given to
    the pair's vehicles, the pair no longer engaged. Computed, for a whole batch, only at a step where some row has a
    pair due (``any_row``). The loop's ``state`` comes and goes as ``packing`` carries it: packed, the conditional
    takes and returns a few arrays, not the loop's dozens, and the exchange writes its records into them."""
    due = packing.unpack(state).due
    return jax.lax.cond(any_row(jnp.any(due)),
                        lambda s: packing.pack(_exchange_due(bodies, watch, packing.unpack(s), pairs=pairs, poles=poles,
                                                             dt=dt, smoothing=smoothing, hitches=hitches, links=links)),
                        lambda s: s, packing.fenced(state))


def _exchange_due(bodies: Bodies, watch: Watch, loop: _Loop, *, pairs, poles, dt, smoothing, hitches=None,
                  links=()) -> _Loop:
    """``_fire``'s exchange (a row with no pair due is returned unchanged), and right after it the hitches' joint
    impulses (``_coupled``), which the exchange's own results leave out and its vehicles' cumulative delta-V
    counts."""
    vehicles = loop.carry.time.shape[0]
    time, engaged, current, carry = loop.time, loop.engaged, loop.current, loop.carry
    p = jnp.argmin(jnp.where(loop.due, engaged, jnp.inf))
    fire = loop.due[p]
    slots_left = loop.count < loop.slot_time.shape[0]
    i, j = jnp.asarray(pairs)[p, 0], jnp.asarray(pairs)[p, 1]
    states = _states(bodies, carry)
    # due within the step: the exchange at its due instant, the bodies carried on from it with their new velocities.
    # The pair is taken back to that instant along its motion, and the contact point with it (the mean of where each
    # body's material point at P was then), so that the impulse's lever arms are those of the positions from which
    # the new velocities run: linear and angular momentum are kept
    when = jnp.clip(engaged[p] + watch.penetration_time[p], time - dt, time)
    lag = time - when
    s1, s2 = _pick(states, i), _pick(states, j)
    at = loop.point[p] - 0.5 * lag * (material_velocity(loop.point[p], s1) + material_velocity(loop.point[p], s2))
    s1, s2 = (s._replace(position=s.position - lag * s.velocity, yaw=s.yaw - lag * s.angular_velocity[2])
              for s in (s1, s2))
    contact = Contact(at, loop.normal[p], watch.restitution[p], watch.friction[p], watch.penetration_time[p])
    pair_states = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), s1, s2)
    ok, velocity, angular = _impulse(_pick(bodies.vehicle, i), s1, _pick(bodies.vehicle, j), s2, contact, smoothing)
    do = fire & slots_left & ok
    new = current[p] < 0
    interaction = jnp.where(new, loop.interactions, current[p])
    loop = loop._replace(exhausted=loop.exhausted | (fire & ~slots_left))
    loop = _record(loop, pair_states, contact, when, jnp.stack([i, j]).astype(jnp.int32), interaction, do)
    # the impulse's planar part on each vehicle of the pair; a vehicle at rest moves again from now
    s = carry.state
    pos, yaw, vel, rate, moving, clock = s.position, s.yaw, s.velocity, s.yaw_rate, carry.moving, carry.time
    for side, b in enumerate((i, j)):
        hit = do & (b < vehicles)
        b = jnp.minimum(b, vehicles - 1)
        new_v, new_r = velocity[side, :2], angular[side, 2]
        pos = pos.at[b].set(jnp.where(hit, pos[b] + lag * (new_v - vel[b]), pos[b]))
        yaw = yaw.at[b].set(jnp.where(hit, yaw[b] + lag * (new_r - rate[b]), yaw[b]))
        vel = vel.at[b].set(jnp.where(hit, new_v, vel[b]))
        rate = rate.at[b].set(jnp.where(hit, new_r, rate[b]))
        clock = clock.at[b].set(jnp.where(hit & (carry.moving[b] < 1.0), time, clock[b]))
        moving = moving.at[b].set(jnp.where(hit, 1.0, moving[b]))
    carry = carry._replace(state=motion.Planar(pos, yaw, vel, rate), moving=moving, time=clock)
    coupled = jax.tree_util.tree_map(lambda a, b: jnp.where(do, a, b),
                                     _coupled(bodies, carry, time, hitches, links), carry)
    bodies_moved, before, after, yaws = [i, j], [pair_states.velocity[0], pair_states.velocity[1]], [], []
    for side, b in enumerate((i, j)):  # the pair's velocities after the exchange and the joints
        b = jnp.minimum(b, vehicles - 1)
        after.append(jnp.where((i, j)[side] < vehicles, _planar3(coupled.state.velocity[b], velocity[side]),
                               velocity[side]))
    yaws += [s1.yaw, s2.yaw]
    moved = [do, do]
    for v in sorted({u for link in links for u in link}):  # the vehicles a joint moved with the pair
        group = joint.components(links, vehicles)[v]
        moved.append(do & (v != i) & (v != j) & functools.reduce(operator.or_, [(i == u) | (j == u) for u in group]))
        bodies_moved.append(v)
        before.append(_planar3(vel[v], jnp.zeros(3, vel.dtype)))
        after.append(_planar3(coupled.state.velocity[v], jnp.zeros(3, vel.dtype)))
        yaws.append(yaw[v])
    loop = _cumulate(loop, jnp.stack(before), jnp.stack(after), bodies_moved, yaws, interaction, jnp.stack(moved),
                     vehicles)
    carry = coupled
    cleared = (jnp.arange(len(pairs)) == p) & fire
    # the separations the next step interpolates its touches from: those of the positions the exchange left
    gap = jnp.where(do, gaps(bodies, _states(bodies, carry), pairs, poles), loop.gap)
    return loop._replace(carry=carry, gap=gap, engaged=jnp.where(cleared, jnp.inf, engaged), due=loop.due & ~cleared,
                         current=jnp.where(cleared & do & new, interaction, current),
                         interactions=loop.interactions + (do & new).astype(jnp.int32))


def _busy(loop: _Loop):
    """A vehicle still moves, or a pair is engaged: the watched motion goes on."""
    return jnp.any(loop.carry.moving >= 1.0) | jnp.any(~jnp.isinf(loop.engaged))


def _run(watch_step, fire, loop: _Loop, n: int, pairs: int, sample, reverse, packed: bool):
    """The loop over the steps (``n`` at most, ``motion_loop.drive``): (the final loop, the samples of ``sample`` after
    every step, or None). Each step watches, then makes the exchanges due: ``pairs`` turns of ``fire``, as many as
    may be due at once, as a loop of its own (unrolled, the program would hold a copy of the exchange per pair, and
    its compile time would grow with the number of pairs). ``packed``: the loop's state is carried packed
    (``packing.Packing``); ``watch_step`` takes and returns a ``_Loop``, ``fire`` (state, packing) the state as
    carried."""
    packing = Packing(loop, packed)

    def step(state):
        state = packing.pack(watch_step(packing.unpack(state)))
        if pairs == 1:
            return fire(state, packing)
        return jax.lax.fori_loop(0, pairs, lambda _, turn: fire(turn, packing), state)

    final, samples = motion_loop.drive(step, packing.pack(loop), n, lambda state: _busy(packing.unpack(state)),
                                       sample=None if sample is None else lambda state: sample(packing.unpack(state)),
                                       reverse=reverse)
    return packing.unpack(final), samples


def _slot_results(bodies: Bodies, first: ExchangeResult, final: _Loop, used, smoothing) -> ExchangeResult:
    """Every slot's results (``collision.exchange`` of its recorded states and contact; slot 0 the first exchange's
    own), NaN in the unused slots."""
    pair = final.slot_between
    full = jax.vmap(lambda a, b, s, c: exchange(_pick(bodies.vehicle, a), _pick(s, 0), _pick(bodies.vehicle, b),
                                                _pick(s, 1), c, smoothing))(
        pair[:, 0], pair[:, 1], final.slot_states, final.slot_contact)
    full = jax.tree_util.tree_map(lambda x, f: x.at[0].set(f), full, first._replace(rest=None, interactions=None))
    return jax.vmap(mask_invalid)(full, used)


def interact(bodies: Bodies, start: motion.Planar, first: ExchangeResult, first_pair, watch: Watch, *,
             max_exchanges: int = MAX_EXCHANGES, dt: float = motion.TIME_STEP,
             time_limit: float = motion.TIME_LIMIT, poles=(), smoothing=0.0, path: bool = False,
             reverse: bool = False, hitches: joint.Hitch | None = None, links=(), at=None,
             packed: bool = False) -> Interactions:
    """The watched motion from the first exchange (``Interactions``).

    ``bodies``: the case's bodies (``Bodies``); ``start``: a ``motion.Planar`` of (V, ...) leaves, each vehicle at the
    first exchange's instant, with its velocity and yaw rate after it; ``first``: the first exchange's result (its
    pair's ``vehicles``); ``first_pair``: its two bodies' indices (static; the first, its vehicle 1, a vehicle);
    ``watch``: the later exchanges' settings per pair (``pairs_of`` order). Static: ``max_exchanges`` (slots, the
    first exchange's included), ``dt``, ``time_limit`` s, ``poles`` (indices of the bodies that are poles),
    ``smoothing`` (of the exchanges), ``path`` (each vehicle's rest result keeps its path) and ``reverse``
    (``motion_loop.drive``). ``hitches`` (a ``joint.Hitch`` of (H, ...) leaves) and ``links`` (static: each hitch's
    (towed, tow) vehicles): the joints (``model.joint``), whose impulse right after the first exchange is given to
    ``start``; a hitched pair is not watched. ``at``: None, or times (V, T) s from the first exchange at which the
    result's ``at`` gives each vehicle's state (NaN where a vehicle has fewer). ``packed`` (static): the loop carries
    its state, and passes the pairs' values to their close look, packed, one flat array per dtype
    (``packing.Packing``): fewer copies and kernels a step, as an accelerator's path asks (``backend.Plan``); the same
    values, to the rounding of a program fused otherwise."""
    vehicles = start.yaw.shape[0]
    fixed = bodies.fixed.yaw.shape[0]
    links = tuple(tuple(link) for link in links)
    pairs = pairs_of(vehicles, fixed, links)
    watched = tuple(sorted(first_pair))  # the pair as ``pairs_of`` lists it; its exchange's vehicle 1 may be either
    if watched not in pairs or first_pair[0] >= vehicles:
        raise ValueError(f"interact: the first exchange's pair {tuple(first_pair)} is not one of the pairs {pairs} "
                         "with a vehicle first")
    dtype = start.yaw.dtype
    exchanged = first.contact.status == OK
    unjoined = start
    if links:  # the joints' impulse right after the first exchange, and the hitch points together from there on
        coupled = joint.couple(start, bodies.motion.mass, bodies.motion.izz, hitches, links)
        start = jax.tree_util.tree_map(lambda a, b: jnp.where(exchanged, a, b), coupled, start)
    carry = jax.vmap(motion.start_carry)(start)
    position, yaw, velocity, yaw_rate = _planes(bodies, carry)
    states = jax.vmap(_state3)(position, yaw, velocity, yaw_rate, bodies.z)
    # the gaps the first step interpolates its touches from (the centroids and normals are the first step's own)
    gap = watch_gaps(bodies, states, carry.moving >= 1.0, pairs, tuple(poles))
    point = jnp.zeros((len(pairs), 3), dtype)
    k = max_exchanges
    zeros = lambda tree, *lead: jax.tree_util.tree_map(  # noqa: E731
        lambda x: jnp.zeros(lead + jnp.shape(x), jnp.result_type(x)), tree)
    pair0 = jnp.asarray(first_pair, jnp.int32)
    # the first exchange's interaction lasts while its pair's footprints overlap
    current = jnp.full((len(pairs),), -1, jnp.int32).at[pairs.index(watched)].set(0)
    loop = _Loop(carry, jnp.zeros((), dtype), jnp.zeros((), jnp.int32), gap, point, point,
                 jnp.full((len(pairs),), jnp.inf, dtype), jnp.zeros(len(pairs), bool), current,
                 jnp.ones((), jnp.int32), zeros(_pick(states, 0), k, 2),
                 zeros(Contact(point[0], point[0], *(gap[0],) * 3), k), jnp.zeros(k, dtype),
                 jnp.zeros((k, 2), jnp.int32),
                 jnp.zeros(k, jnp.int32), jnp.zeros((), jnp.int32), jnp.full((vehicles,), -1, jnp.int32),
                 jnp.zeros((vehicles, 3), dtype), jnp.zeros((vehicles, 3), dtype), jnp.zeros((vehicles, 3), dtype),
                 jnp.zeros(vehicles, dtype), jnp.zeros((), bool))
    if at is not None:
        at = jnp.asarray(at, dtype)
        loop = loop._replace(caught=(at, jnp.zeros(at.shape, bool), jnp.full(at.shape + (7,), jnp.nan, dtype)))
    # slot 0 is the first exchange, whose results are given (its states are not needed again)
    loop = loop._replace(count=jnp.ones((), jnp.int32), slot_between=loop.slot_between.at[0].set(pair0))
    after = [v.velocity_after for v in first.vehicles]
    before = [a - v.delta_v for a, v in zip(after, first.vehicles)]
    moved, yaws = list(first_pair), [states.yaw[first_pair[0]], states.yaw[first_pair[1]]]
    after = [_planar3(start.velocity[b], a) if b < vehicles else a for b, a in zip(first_pair, after)]
    group = set()
    for b in first_pair:  # the vehicles the joints moved with the pair
        group |= set(joint.components(links, vehicles)[b]) if b < vehicles else set()
    for v in sorted(group - set(first_pair)):
        moved.append(v)
        yaws.append(states.yaw[v])
        before.append(_planar3(unjoined.velocity[v], jnp.zeros(3, dtype)))
        after.append(_planar3(start.velocity[v], jnp.zeros(3, dtype)))
    loop = _cumulate(loop, jnp.stack(before), jnp.stack(after), moved, yaws, jnp.zeros((), jnp.int32), exchanged,
                     vehicles)
    advance = motion.step_function(reverse and not path)
    watch_step = lambda lp: _watch_step(bodies, watch, lp, pairs=pairs, poles=tuple(poles), dt=dt,  # noqa: E731
                                        advance=advance, hitches=hitches, links=links, packed=packed)
    fire = lambda state, packing: _fire(bodies, watch, state, packing, pairs=pairs,  # noqa: E731
                                        poles=tuple(poles), dt=dt, smoothing=smoothing, hitches=hitches, links=links)
    sample = (lambda lp: jax.vmap(motion_loop.path_sample)(lp.carry)) if path else None
    final, samples = _run(watch_step, fire, loop, motion_loop.steps_for(time_limit, dt), len(pairs), sample, reverse,
                          packed)
    rest = tuple(motion_loop.rest_result(_pick(start, v), _pick(final.carry, v),
                                    None if samples is None else samples[:, v]) for v in range(vehicles))
    used = jnp.arange(k) < final.count
    exchanges = _slot_results(bodies, first, final, used, smoothing)
    energy = jnp.sum(jnp.where(used, exchanges.contact.energy_loss, 0.0))
    in_one = final.first_interaction >= 0
    cumulative = jnp.where(in_one[:, None], final.after - final.before, 0.0)
    # the cumulative delta-V in the vehicle's frame at its first exchange: the direction the force came from
    sin, cos = la.sincos(final.heading)
    body = jnp.stack([cos * cumulative[:, 0] + sin * cumulative[:, 1], cos * cumulative[:, 1] - sin * cumulative[:, 0],
                      cumulative[:, 2]], axis=-1)
    pdof = jax.vmap(pdof_degrees)(body)
    end = gaps(bodies, _states(bodies, final.carry), pairs, tuple(poles))
    states_at = None
    if at is not None:  # a time after the motion's end: the state it ended in; one not after the exchange: none
        times, found, values = final.caught
        values = jnp.where((~found & (times > 0))[..., None], _row(final.carry)[:, None], values)
        states_at = state_at(values)
    return Interactions(exchanges, final.slot_time, final.slot_between, final.slot_interaction, final.count,
                        cumulative, final.impulses, final.first_interaction, pdof, energy, final.exhausted,
                        end < 0, jnp.maximum(-end, 0.0), rest, states_at)
