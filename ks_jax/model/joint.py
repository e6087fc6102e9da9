"""Hitches: planar pin joints between a tow and the vehicle it tows (docs/model.md, "Articulated vehicles").

A hitch is a point of each of two vehicles, ``point`` in the towed vehicle's body frame and ``point_on_tow`` in its
tow's; the joint keeps the two together and lets the vehicles turn freely about it, or up to ``max_angle`` either
way (the articulation: the towed vehicle's yaw minus its tow's). The joint acts by impulses, as the exchanges do:

- after each step of the motion, an impulse at the hitch (and, where the articulation is at its limit and opening,
  an equal and opposite yaw impulse) brings the two hitch points to one velocity: the limit, as the step shrinks,
  of the constraint force; then the same rule applied to the positions (a correction that moves each body by its
  share, inverse to its mass and yaw inertia) puts the hitch points together again, so that they never drift;
- right after an exchange, the same impulse at the velocities the exchange left: perfectly plastic, the joint's
  impulse that the exchange itself ignores.

Both are the solution of one linear system per hitch: for the generalized impulse (Jx, Jy, L), the change of the
constraint's velocity (the hitch points' relative velocity, the relative yaw rate) is K (Jx, Jy, L), with
K = A_t M_t^-1 A_t^T + A_w M_w^-1 A_w^T (A the map from a body's (vx, vy, yaw rate) to its hitch point's velocity and
its yaw rate, M its mass and yaw inertia). Several hitches (a tractor with two trailers) are solved one after the
other, a few times over. Internal impulses: the bodies' total linear momentum, and their angular momentum about any
point, are unchanged by them.

A semi-trailer's front is carried by its tow (``fifth_wheel``): ``carried`` moves the trailer's share of its weight
from its front wheels (which are not there) to the tow's axles at the hitch, so that the tyres' loads are those of the
combination.

Everything here is pure and unbatched; the links (which vehicles each hitch couples) are static.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from . import linalg as la
from .motion import Body, Planar

SWEEPS = 4  # passes over the hitches where there are several (one hitch is solved exactly in one)
LIMIT_TOLERANCE = 1e-6  # rad: an articulation this close to its limit counts as at it


class Hitch(NamedTuple):
    """One hitch's points and limit: ``point`` (2,) m in the towed vehicle's body frame, ``point_on_tow`` (2,) m in
    its tow's, ``max_angle`` () rad (inf for none)."""

    point: jnp.ndarray
    point_on_tow: jnp.ndarray
    max_angle: jnp.ndarray


def turned(yaw, p):
    """(2,) the body frame vector ``p`` (2,) turned by ``yaw``: its global direction."""
    s, c = la.sincos(yaw)
    return jnp.stack([c * p[0] - s * p[1], s * p[0] + c * p[1]])


def _perp(r):
    """k x r: the velocity of the point at ``r`` of a body turning at a unit yaw rate."""
    return jnp.stack([-r[1], r[0]])


def _moment(r, j):
    """The yaw moment of the force (or impulse) ``j`` at ``r``: r x j."""
    return r[0] * j[1] - r[1] * j[0]


def follow(tow_position, tow_yaw, tow_velocity, tow_yaw_rate, yaw, yaw_rate, hitch: Hitch):
    """Where a towed vehicle's CG is, and how fast it moves, for its hitch point to be its tow's: ((2,) m, (2,) m/s),
    from the tow's planar state and the towed vehicle's own yaw and yaw rate."""
    r_w, r_t = turned(tow_yaw, hitch.point_on_tow), turned(yaw, hitch.point)
    return (tow_position + r_w - r_t,
            tow_velocity + tow_yaw_rate * _perp(r_w) - yaw_rate * _perp(r_t))


def articulation(yaw, tow_yaw):
    """() rad in (-pi, pi]: the towed vehicle's yaw minus its tow's."""
    s, c = la.sincos(yaw - tow_yaw)
    return la.safe_atan2(s, c)


def hitch_gap(state_towed: Planar, state_tow: Planar, hitch: Hitch):
    """(2,) m: the towed vehicle's hitch point minus its tow's (0 where the joint holds)."""
    return (state_towed.position + turned(state_towed.yaw, hitch.point)
            - state_tow.position - turned(state_tow.yaw, hitch.point_on_tow))


def _rows(r):
    """A: a body's (vx, vy, yaw rate) to its point ``r``'s velocity and its yaw rate."""
    one, zero = jnp.ones_like(r[0]), jnp.zeros_like(r[0])
    return jnp.stack([jnp.stack([one, zero, -r[1]]), jnp.stack([zero, one, r[0]]), jnp.stack([zero, zero, one])])


def _solve(r_t, r_w, inv_t, inv_w, error, limited):
    """The generalized impulse (3,) that takes ``error`` (3,) (the hitch's relative velocity or gap, and the
    articulation's) to zero, with the third row only where ``limited``: K^-1 (-error), K of the module's docstring."""
    a_t, a_w = _rows(r_t), _rows(r_w)
    k = la.mm(a_t, inv_t[:, None] * a_t.T) + la.mm(a_w, inv_w[:, None] * a_w.T)
    unit = jnp.eye(3, dtype=k.dtype)
    keep = jnp.stack([jnp.ones_like(limited), jnp.ones_like(limited), limited])
    k = jnp.where(keep[:, None] & keep[None, :], k, unit)
    rhs = jnp.where(keep, -error, 0.0)
    return la.mm(la.adjugate3(k), rhs) / la.det3(k)


def _limit(state_t: Planar, state_w: Planar, hitch: Hitch):
    """(the articulation's excess over its limit (0 within it), where it is at its limit)."""
    angle = articulation(state_t.yaw, state_w.yaw)
    excess = angle - jnp.clip(angle, -hitch.max_angle, hitch.max_angle)
    at = jnp.abs(angle) >= hitch.max_angle - LIMIT_TOLERANCE
    return excess, angle, at


def _velocities(q, inv, t, w, hitch: Hitch, yaws):
    """The hitch ``(t, w)``'s impulse on the velocities ``q`` (V, 3) (vx, vy, yaw rate): the new ``q``."""
    r_t, r_w = turned(yaws[t], hitch.point), turned(yaws[w], hitch.point_on_tow)
    qt, qw = q[t], q[w]
    relative = (qt[:2] + qt[2] * _perp(r_t)) - (qw[:2] + qw[2] * _perp(r_w))
    state_t = Planar(jnp.zeros(2, q.dtype), yaws[t], qt[:2], qt[2])
    state_w = Planar(jnp.zeros(2, q.dtype), yaws[w], qw[:2], qw[2])
    _, angle, at = _limit(state_t, state_w, hitch)
    spin = qt[2] - qw[2]
    opening = at & (spin * angle > 0)
    lam = _solve(r_t, r_w, inv[t], inv[w], jnp.concatenate([relative, spin[None]]), opening)
    j, moment = lam[:2], lam[2]
    dq_t = inv[t] * jnp.concatenate([j, (_moment(r_t, j) + moment)[None]])
    dq_w = inv[w] * jnp.concatenate([j, (_moment(r_w, j) + moment)[None]])
    return q.at[t].add(dq_t).at[w].add(-dq_w)


def _positions(p, inv, t, w, hitch: Hitch):
    """The hitch ``(t, w)``'s correction of the positions and yaws ``p`` (V, 3) (x, y, yaw): the new ``p``."""
    r_t, r_w = turned(p[t, 2], hitch.point), turned(p[w, 2], hitch.point_on_tow)
    gap = p[t, :2] + r_t - p[w, :2] - r_w
    zero = jnp.zeros(2, p.dtype)
    excess, _, _ = _limit(Planar(zero, p[t, 2], zero, zero[0]), Planar(zero, p[w, 2], zero, zero[0]), hitch)
    lam = _solve(r_t, r_w, inv[t], inv[w], jnp.concatenate([gap, excess[None]]), excess != 0)
    j, moment = lam[:2], lam[2]
    dp_t = inv[t] * jnp.concatenate([j, (_moment(r_t, j) + moment)[None]])
    dp_w = inv[w] * jnp.concatenate([j, (_moment(r_w, j) + moment)[None]])
    return p.at[t].add(dp_t).at[w].add(-dp_w)


def couple(state: Planar, mass, izz, hitches: Hitch, links, *, positions: bool = True) -> Planar:
    """The vehicles' planar ``state`` ((V, ...) leaves) with every hitch's joint impulse given (the module's
    docstring), and, where ``positions`` (static), their hitch points put together again. ``mass``, ``izz`` (V,);
    ``hitches``: a ``Hitch`` of (H, ...) leaves, one per link; ``links`` (static): each hitch's (towed, tow)
    vehicle indices. Without links, ``state`` itself."""
    if not links:
        return state
    inv = jnp.stack([1.0 / mass, 1.0 / mass, 1.0 / izz], axis=-1)
    sweeps = 1 if len(links) == 1 else SWEEPS
    pick = [Hitch(*(x[h] for x in hitches)) for h in range(len(links))]
    q = jnp.concatenate([state.velocity, state.yaw_rate[:, None]], axis=-1)
    for _ in range(sweeps):
        for h, (t, w) in enumerate(links):
            q = _velocities(q, inv, t, w, pick[h], state.yaw)
    position, yaw = state.position, state.yaw
    if positions:
        p = jnp.concatenate([position, yaw[:, None]], axis=-1)
        for _ in range(max(2, sweeps)):  # twice at least: the correction is linear in the turn it makes
            for h, (t, w) in enumerate(links):
                p = _positions(p, inv, t, w, pick[h])
        position, yaw = p[:, :2], p[:, 2]
    return Planar(position, yaw, q[:, :2], q[:, 2])


def components(links, vehicles: int):
    """(static) For each vehicle, the vehicles coupled to it through hitches, itself included, in index order."""
    group = list(range(vehicles))

    def root(v):
        while group[v] != v:
            v = group[v]
        return v

    for t, w in links:
        group[root(t)] = root(w)
    return tuple(tuple(u for u in range(vehicles) if root(u) == root(v)) for v in range(vehicles))


def carried(tow: Body, towed: Body, hitch: Hitch):
    """(tow, towed): the two vehicles' ``motion.Body`` where the towed vehicle's front is carried by its tow at the
    hitch (a semi-trailer on its fifth wheel). The towed vehicle's weight is shared between the hitch (``point``) and
    its axle group (its rear wheels) by their distances from its CG; its front wheels carry nothing; the hitch's share
    is added to the tow's axles by the hitch's distances from them (``point_on_tow``). Each body's load transfer is its
    own mass's (the tow's does not count the trailer's share)."""
    x_hitch, x_axle = hitch.point[0], towed.x[2]
    share = -x_axle / (x_hitch - x_axle)  # the hitch's share of the towed vehicle's weight
    kingpin = share * towed.weight
    axle = towed.weight - kingpin
    zero = jnp.zeros_like(axle)
    per_g = towed.lateral[1] + towed.lateral[3]  # m h / t: the lateral transfer per unit of lateral acceleration
    towed = towed._replace(static=0.5 * jnp.stack([zero, zero, axle, axle]), pitch=jnp.zeros_like(towed.pitch),
                           lateral=per_g * (axle / towed.weight) * jnp.stack([zero, zero, zero - 1.0, zero + 1.0]),
                           weight=axle)
    x_front, x_rear = tow.x[0], tow.x[2]
    front = kingpin * (hitch.point_on_tow[0] - x_rear) / (x_front - x_rear)
    tow = tow._replace(static=tow.static + 0.5 * jnp.stack([front, front, kingpin - front, kingpin - front]),
                       weight=tow.weight + kingpin)
    return tow, towed
