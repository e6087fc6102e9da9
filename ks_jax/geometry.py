"""Automatic contact (MODEL.md section 5): footprints, first contact, overlap, centroid, normal.

Everything here is pure and unbatched, built from fixed-size arrays (a rectangle is (4, 2), an
overlap polygon (8, 2) with a vertex count), so it works under ``jax.jit``, ``jax.vmap`` and
``jax.grad``; ``automatic_exchange`` is the entry point that ``ks_jax.solve`` calls.

Choices where MODEL.md is silent
--------------------------------
- Footprint: the bounding box seen from above, x in [cg_to_front - length, cg_to_front],
  y in [-width/2, width/2] in the body frame, turned by the yaw only (pitch and roll are
  ignored for the footprint and the vertical overlap).
- Free motion: the CG moves with its constant velocity (3D, so z too); the body turns about
  its CG at the constant yaw rate (z component of the global angular velocity). Pitch and roll
  stay as given; velocities and angular velocities are unchanged.
- ``time`` (``contact.time``) reports the first-contact time t_i, as the manual's "timing"
  panel does; the exchange itself happens at t_i + penetration_time. For an explicit contact
  (``ks_jax.exchange``) time is 0: the exchange is at the case state.
- First contact is searched in [0, HORIZON] = [0, 10] s. Where neither vehicle rotates it is
  exact (closed form: the separating-axis test swept along the relative translation is a set
  of 8 linear inequalities in t). Where one rotates, the search keeps to the reach window
  (``reach_window``): the times at which the circles about the CGs that hold each footprint
  at any yaw overlap, which the CGs' straight paths give in closed form; outside it the
  footprints cannot touch, and vehicles that never come within reach are "no_contact"
  without a search. Inside it, the separating-axis function s(t) = max over the 4 edge
  normals of the gap between the projections (> 0 apart, <= 0 touching) is advanced
  conservatively: s(t) is at most the distance between the footprints, which shrinks at most
  at |v_1 - v_2| + |w_1| R_1 + |w_2| R_2, so no touch comes before t + s(t) / that bound.
  Each step is that long but at least (window length) / SCAN_STEPS: 5 ms at most, and about
  0.2 ms where two cars pass at 20 m/s. Only a graze shorter than that least step, and only
  once the footprints are within a step's travel of each other, can be missed. The step that
  lands on s <= 0 brackets the touch, refined by regula falsi (Illinois), aimed a hair inside
  the touch so that it lands on the touching side, with a bisection wherever a step fails to
  halve the bracket: it ends at a time where the footprints touch, overlapping by at most
  16 machine epsilons of R_1 + R_2 (about 1e-14 m; within ~1e-13 s of the exact touch), in
  4-11 evaluations of s where 48 bisections took 48 (``_refine``; REFINE_STEPS caps it).
- Gradients of t_i are those of the touching condition s(t_i, theta) = 0 (implicit function
  theorem, applied as one Newton step from a stop_gradient root), so they see speeds,
  headings, positions and yaw rates in both cases; 0 when the vehicles overlap at t = 0.
- Overlap: vehicle 1's footprint clipped by vehicle 2's four half-planes (Sutherland-Hodgman,
  8 vertices at most). Its area centroid is the impulse centroid; z is the middle of the
  boxes' vertical overlap, [z - cg_height, z - cg_height + height] of each.
- Degenerate overlap (no wider than ~1e3 machine epsilons of the vehicles' size: its area below
  that length times half its perimeter, e.g. when penetration_time = 0 and the exchange is at the
  instant of touching): the centroid is the
  middle of the touching features (the contact manifold along the axis of least penetration),
  which is the limit of the area centroid as penetration_time -> 0. Its derivative in
  penetration_time is the growing overlap's (``_overlap_growth``: for a corner entering a side,
  the centroid of a growing triangle, a third of the way in, which the corner does not give);
  at the touch itself (penetration_time 0, point and normal automatic) both crushes are 0, with
  the growing overlap's derivative too. These are the one-sided derivatives from
  penetration_time > 0; the derivatives in every other input are those of the touching
  configuration, which stays touching.
- Normal: perpendicular to the line through the two points where the outlines cross,
  horizontal, pointing from vehicle 2 into vehicle 1: to the side of that line where footprint
  1's centre lies relative to footprint 2's (n . (c_1 - c_2) > 0; the axis of least penetration
  decides only if that product is exactly 0), then tilted up by ``normal_pitch``:
  n = (cos p n_x, cos p n_y, sin p). The axis of least penetration would not do for the sign:
  once a penetration is deeper than the overlap is wide, that axis turns across the line, and its
  sign no longer says which way vehicle 1 lies (an inline rear-end came out "separating"). Nor
  would the CGs: a CG may sit anywhere along its box, and one 1 ft behind the front face is
  passed by the other's within a foot of penetration; the boxes' centres are passed only when
  the penetration is half a box long. Where the outlines do not cross in exactly two points more
  than ~1e-12 m inside both edges (collinear edges, also when rounding parts them by 1e-16 m;
  containment; a degenerate overlap) n is the axis of least penetration.
- Coordinates: the search and the geometry work about the CGs' midpoint, and the tolerances above
  (~1e3 machine epsilons of the vehicles' size) grow with the scene's distance from the origin, so
  that a scene given in survey coordinates (1e4-1e6 m) gives the contact of the same scene near the
  origin: its edges collinear within the input's own rounding stay collinear.
- Touched, then parted: where the footprints no longer overlap at t_i + penetration_time (a
  glancing touch shorter than the penetration time), there is no overlap to put the centroid in:
  status INVALID_PARTED ("penetration_time is too long"), NaN results, as for other bad input.
- Never touching within the horizon: status "no_contact" and no NaN anywhere: zero impulse,
  zero delta-V, velocity_after = velocity, crush and EES 0, ``time`` = HORIZON, point the
  midpoint of the CGs and normal the horizontal direction from CG 2 to CG 1, both at t = 0.
- Inputs that break a rule (``ks_jax.exchange.input_status``) give that status and NaN
  results, exactly as ``ks_jax.exchange`` does; the geometry of such a row runs on harmless
  stand-in values so that neither it nor its gradient can produce NaN elsewhere.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import derived
from . import linalg as la
from .exchange import _benign, exchange, fence, input_status
from .derived import mask_invalid
from .types import INVALID_PARTED, NO_CONTACT, OK, Contact, ExchangeResult, State, Vehicle

HORIZON = 10.0  # s, search horizon for the first contact
SCAN_STEPS = 2000  # the least step where a vehicle rotates: the reach window / SCAN_STEPS (<= 5 ms)
REFINE_STEPS = 128  # a cap on ``_refine``: a bracket of 10 s takes ~53 halvings to a few ulps, at most 2 steps each
MAX_VERTICES = 8  # two convex quadrilaterals overlap in at most an octagon


class Contact2D(NamedTuple):
    """The automatic contact at one instant: point (3,) m, normal (3,) horizontal unit
    (from vehicle 2 into vehicle 1), overlap polygon (8, 2) m with ``count`` vertices,
    ``area`` () m^2, ``crossings`` (2, 2) m and ``crossing_ok`` () bool (the two outline
    crossings and whether the normal came from them), ``solid`` () bool (the area is above its
    tolerance: the point is the area centroid, else the middle of the touching features)."""

    point: jnp.ndarray
    normal: jnp.ndarray
    polygon: jnp.ndarray
    count: jnp.ndarray
    area: jnp.ndarray
    crossings: jnp.ndarray
    crossing_ok: jnp.ndarray
    solid: jnp.ndarray


# ---------------------------------------------------------------------------------------
# footprints and free motion


def footprint(vehicle: Vehicle, xy, yaw):
    """(4, 2) corners (m) of the footprint with CG at ``xy`` (2,) and ``yaw`` (rad),
    counter-clockwise: rear-right, front-right, front-left, rear-left."""
    a = vehicle.cg_to_front - vehicle.length
    b = vehicle.cg_to_front
    h = 0.5 * vehicle.width
    bx = jnp.stack([a, b, b, a])
    by = jnp.stack([-h, -h, h, h])
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([xy[0] + c * bx - s * by, xy[1] + s * bx + c * by], -1)


def advance(state: State, t) -> State:
    """The state after free motion for ``t`` s: CG moved by velocity * t, yaw turned by the yaw
    rate * t; everything else unchanged."""
    return state._replace(position=state.position + state.velocity * t,
                          yaw=state.yaw + state.angular_velocity[2] * t)


def _footprint_at(vehicle, state, t):
    return footprint(vehicle, state.position[:2] + state.velocity[:2] * t, state.yaw + state.angular_velocity[2] * t)


def _axes(yaw1, yaw2):
    """(4, 2) unit edge normals of both footprints."""
    c1, s1, c2, s2 = jnp.cos(yaw1), jnp.sin(yaw1), jnp.cos(yaw2), jnp.sin(yaw2)
    return jnp.stack([jnp.stack([c1, s1]), jnp.stack([-s1, c1]), jnp.stack([c2, s2]), jnp.stack([-s2, c2])])


def penetrations(corners1, corners2, axes):
    """(8,) overlap of the projections on each axis, for vehicle 1 on the + side of vehicle 2
    (first 4) and on the - side (last 4). All >= 0 iff the footprints touch."""
    p1 = corners1 @ axes.T  # (4 corners, 4 axes)
    p2 = corners2 @ axes.T
    plus = jnp.max(p2, 0) - jnp.min(p1, 0)
    minus = jnp.max(p1, 0) - jnp.min(p2, 0)
    return jnp.concatenate([plus, minus])


def separation(vehicle1, state1, vehicle2, state2, t):
    """s(t) () m: the largest gap between the footprints' projections on their edge normals at
    time t of free motion; > 0 apart, <= 0 touching or overlapping."""
    c1 = _footprint_at(vehicle1, state1, t)
    c2 = _footprint_at(vehicle2, state2, t)
    axes = _axes(state1.yaw + state1.angular_velocity[2] * t, state2.yaw + state2.angular_velocity[2] * t)
    return -jnp.min(penetrations(c1, c2, axes))


def least_penetration_normal(corners1, corners2, axes):
    """(2,) unit axis of least penetration, from vehicle 2 into vehicle 1 (or, when apart, the
    most separating axis, pointing the same way), and the penetration depth () m."""
    pen = penetrations(corners1, corners2, axes)
    k = jnp.argmin(pen)
    sign = jnp.where(k < 4, 1.0, -1.0)
    return sign * axes[k % 4], pen[k]


# ---------------------------------------------------------------------------------------
# first contact


def _translation_contact(vehicle1, state1, vehicle2, state2):
    """Closed form where neither vehicle rotates: (t_i, found). All 8 penetrations are linear
    in t, f_k(t) = f_k + g_k t, and the footprints touch iff all are >= 0."""
    c1 = _footprint_at(vehicle1, state1, 0.0)
    c2 = _footprint_at(vehicle2, state2, 0.0)
    axes = _axes(state1.yaw, state2.yaw)
    f = penetrations(c1, c2, axes)
    rate = axes @ (state1.velocity[:2] - state2.velocity[:2])  # d/dt of vehicle 1's projections
    g = jnp.concatenate([-rate, rate])
    root = la.safe_div(-f, g)
    big = jnp.asarray(1e30, f.dtype)
    lo = jnp.maximum(0.0, jnp.max(jnp.where(g > 0, root, -big)))
    hi = jnp.min(jnp.where(g < 0, root, big))
    feasible = jnp.all((g != 0) | (f >= 0))
    found = feasible & (lo <= hi) & (lo <= HORIZON)
    return lo, found


def _reach(vehicle):
    """() m: the radius about the CG of the circle that holds the footprint at any yaw."""
    far = jnp.maximum(jnp.abs(vehicle.cg_to_front), jnp.abs(vehicle.cg_to_front - vehicle.length))
    return jnp.sqrt(far * far + 0.25 * vehicle.width * vehicle.width)


def reach_window(vehicle1, state1, vehicle2, state2):
    """(t_a, t_b, within): the times t >= 0 at which the footprints' circles of reach (``_reach``
    about each CG, moving with the CG) overlap, whatever the vehicles' yaw rates: the footprints
    can touch only then. ``within`` is False where the circles never overlap; t_b is inf where
    they overlap for ever (equal velocities). The circles are 0.1% larger than they need be, so
    that rounding cannot shut out a touch."""
    r = 1.001 * (_reach(vehicle1) + _reach(vehicle2))
    d = state1.position[:2] - state2.position[:2]
    dv = state1.velocity[:2] - state2.velocity[:2]
    a, b, c = jnp.sum(dv * dv), jnp.sum(d * dv), jnp.sum(d * d) - r * r
    # |d + dv t|^2 <= r^2  <=>  a t^2 + 2 b t + c <= 0; the roots in forms free of cancellation
    disc = b * b - a * c
    sq = jnp.sqrt(jnp.maximum(disc, 0.0))
    inside = c <= 0
    within = inside | ((b < 0) & (disc >= 0))
    t_a = jnp.where(inside, 0.0, la.safe_div(c, sq - b))
    inf = jnp.asarray(jnp.inf, d.dtype)
    t_b = jnp.where(b < 0, la.safe_div(sq - b, a, inf), la.safe_div(-c, b + sq, inf))
    t_b = jnp.where(a > 0, t_b, inf)
    return t_a, jnp.maximum(t_a, t_b), within


def _scan_contact(vehicle1, state1, vehicle2, state2, skip):
    """Conservative advancement over the part of [0, HORIZON] inside the reach window, then
    ``_refine``: (t_i, found). Rows where ``skip`` is True are not searched (found False).

    s(t) never exceeds the distance between the footprints (a gap between projections on a unit
    axis is at most the distance), and that distance shrinks at most at the closing bound
    |v_1 - v_2| + |w_1| R_1 + |w_2| R_2 (R_i the reach): no touch can come before
    t + s(t) / bound. Each step is that long, but at least (window length) / SCAN_STEPS, and the
    first step that lands on s <= 0 brackets the touch for ``_refine``."""
    t_a, t_b, within = reach_window(vehicle1, state1, vehicle2, state2)
    t_end = jnp.clip(t_b, t_a, HORIZON)
    within = within & (t_a <= HORIZON) & ~skip
    h = (t_end - t_a) / SCAN_STEPS
    dv = state1.velocity[:2] - state2.velocity[:2]
    bound = 1.001 * (la.safe_norm(dv) + jnp.abs(state1.angular_velocity[2]) * _reach(vehicle1)
                     + jnp.abs(state2.angular_velocity[2]) * _reach(vehicle2))
    sep = lambda t: separation(vehicle1, state1, vehicle2, state2, t)  # noqa: E731

    def cond(carry):
        return ~carry[-1]

    def body(carry):
        k, t, s, _, _, _, _ = carry
        t_next = jnp.minimum(t + jnp.maximum(la.safe_div(s, bound, h), h), t_end)
        s_next = sep(t_next)
        found = s_next <= 0
        return k + 1, t_next, s_next, t, s, found, found | (t_next >= t_end) | (k + 1 >= SCAN_STEPS + 2)

    s_a = sep(t_a)
    at_start = within & (s_a <= 0)
    init = (jnp.int32(0), t_a, s_a, t_a, s_a, at_start, ~within | at_start)
    _, t_hit, s_hit, t_before, s_before, found, _ = jax.lax.while_loop(cond, body, init)
    tol = 16 * jnp.finfo(t_hit.dtype).eps * (_reach(vehicle1) + _reach(vehicle2))
    t_root = _refine(sep, t_before, t_hit, s_before, s_hit, tol, found & ~at_start)
    return jnp.where(at_start, t_a, t_root), found


def _refine(sep, lo, hi, s_lo, s_hi, tol, active):
    """A time in [lo, hi] where sep <= 0 and sep >= -tol, given sep(lo) > 0 >= sep(hi): hi itself
    where ``active`` is False or sep(hi) >= -tol already.

    Regula falsi aimed at sep = -tol / 2 (so that where sep is straight, one step lands inside
    the tolerance, on the touching side), with the Illinois rule (the end kept twice in a row has
    its value halved, so that neither end stalls) and a bisection after any step that did not
    halve the bracket: never slower than about two bisections a halving, and under vmap a while
    loop, so rows with nothing to refine skip it. It also ends where the bracket is a few ulps
    wide, or after REFINE_STEPS steps."""
    eps = jnp.finfo(lo.dtype).eps

    def cond(carry):
        k, lo, hi, _, s_hi, _, _ = carry
        return active & (s_hi < -tol) & (hi - lo > 4 * eps * jnp.abs(hi)) & (k < REFINE_STEPS)

    def body(carry):
        k, lo, hi, s_lo, s_hi, kept, last_width = carry
        width = hi - lo
        t_secant = lo + (s_lo + 0.5 * tol) * la.safe_div(width, s_lo - s_hi)
        bisect = (width > 0.5 * last_width) | ~(t_secant > lo) | ~(t_secant < hi)
        t = jnp.where(bisect, 0.5 * (lo + hi), t_secant)
        s = sep(t)
        touching = s <= 0
        s_lo = jnp.where(touching, jnp.where(kept == 1, 0.5 * s_lo, s_lo), s)
        s_hi = jnp.where(touching, s, jnp.where(kept == -1, 0.5 * s_hi, s_hi))
        kept = jnp.where(touching, jnp.int32(1), jnp.int32(-1))  # 1: lo kept, -1: hi kept
        last_width = jnp.where(bisect, jnp.inf, width)
        return k + 1, jnp.where(touching, lo, t), jnp.where(touching, t, hi), s_lo, s_hi, kept, last_width

    inf = jnp.asarray(jnp.inf, lo.dtype)
    init = (jnp.int32(0), lo, hi, s_lo, s_hi, jnp.int32(0), inf)
    return jax.lax.while_loop(cond, body, init)[2]


def first_contact(vehicle1, state1, vehicle2, state2):
    """First time t_i >= 0 (s) at which the footprints touch under free motion, and whether
    they were found to: ((), bool ()). Differentiable through the touching condition."""
    params = jax.lax.stop_gradient((vehicle1, state1, vehicle2, state2))
    translating = (params[1].angular_velocity[2] == 0) & (params[3].angular_velocity[2] == 0)
    t_lin, found_lin = _translation_contact(*params)
    t_rot, found_rot = _scan_contact(*params, translating)
    t0 = jnp.where(translating, t_lin, t_rot)
    found = jnp.where(translating, found_lin, found_rot)
    t0 = jnp.where(found, t0, 0.0)

    # implicit differentiation: t = t0 - (s(t0, theta) - s(t0, theta0)) / s_t(t0, theta0)
    s_theta, s_t = jax.jvp(lambda t: separation(vehicle1, state1, vehicle2, state2, t), (t0,), (jnp.ones_like(t0),))
    correction = la.safe_div(s_theta - jax.lax.stop_gradient(s_theta), jax.lax.stop_gradient(s_t))
    t = t0 - jnp.where(found & (t0 > 0), correction, 0.0)
    return t, found


# ---------------------------------------------------------------------------------------
# overlap polygon


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _next_index(count):
    idx = jnp.arange(MAX_VERTICES)
    return idx, jnp.where(idx + 1 < count, idx + 1, 0)


def _clip(poly, count, a, b):
    """Clip the convex polygon (8, 2) with ``count`` vertices by the half-plane left of the
    directed line a -> b (Sutherland-Hodgman step). Returns (poly, count)."""
    idx, nxt = _next_index(count)
    valid = idx < count
    q = poly[nxt]
    edge = b - a
    d0 = _cross2(edge, poly - a)
    d1 = _cross2(edge, q - a)
    in0, in1 = d0 >= 0, d1 >= 0
    crossing = valid & (in0 != in1)
    s = la.safe_div(d0, d0 - d1)
    x = poly + s[:, None] * (q - poly)
    cand = jnp.stack([poly, x], 1).reshape(2 * MAX_VERTICES, 2)
    keep = jnp.stack([valid & in0, crossing], 1).reshape(2 * MAX_VERTICES)
    pos = jnp.cumsum(keep) - 1
    onehot = ((pos[:, None] == jnp.arange(MAX_VERTICES)[None, :]) & keep[:, None]).astype(poly.dtype)
    return onehot.T @ cand, jnp.minimum(jnp.sum(keep), MAX_VERTICES).astype(jnp.int32)


def overlap_polygon(corners1, corners2):
    """Footprint 1 clipped by footprint 2 (both (4, 2), counter-clockwise): (8, 2) vertices, of
    which the first ``count`` () are used."""
    poly = jnp.zeros((MAX_VERTICES, 2), corners1.dtype).at[:4].set(corners1)

    def step(carry, edge):
        return _clip(*carry, edge[0], edge[1]), None

    edges = jnp.stack([corners2, jnp.roll(corners2, -1, 0)], 1)  # (4, 2 ends, 2)
    (poly, count), _ = jax.lax.scan(step, (poly, jnp.int32(4)), edges)
    return poly, count


def polygon_area_centroid(poly, count):
    """Area () m^2 and area centroid (2,) m of the polygon's first ``count`` vertices (the
    vertex mean where the area is 0)."""
    idx, nxt = _next_index(count)
    valid = idx < count
    w = jnp.where(valid[:, None], poly, 0.0)
    origin = jnp.sum(w, 0) / jnp.maximum(count, 1)
    p = jnp.where(valid[:, None], poly - origin, 0.0)
    q = p[nxt]
    cr = jnp.where(valid, _cross2(p, q), 0.0)
    area = 0.5 * jnp.sum(cr)
    moment = jnp.sum((p + q) * cr[:, None], 0) / 6.0
    return area, origin + jnp.stack([la.safe_div(moment[0], area), la.safe_div(moment[1], area)])


def outline_crossings(corners1, corners2, tol=0.0):
    """Points where the two outlines cross: (16, 2) candidates (edge i of 1 x edge j of 2),
    (16,) mask: proper crossings only, more than ``tol`` (m) inside both edges and between edges
    more than ~tol / length from parallel, so that collinear edges and corners lying on edges do
    not count, also where rounding moves them apart by far less than ``tol`` (a scene turned by
    30 deg puts the corners of an inline crash 1e-16 m off each other's edges)."""
    a = corners1
    da = jnp.roll(corners1, -1, 0) - corners1
    b = corners2
    db = jnp.roll(corners2, -1, 0) - corners2
    a, da = a[:, None, :], da[:, None, :]
    b, db = b[None, :, :], db[None, :, :]
    denom = _cross2(da, db)
    ab = b - a
    s = la.safe_div(_cross2(ab, db), denom)
    t = la.safe_div(_cross2(ab, da), denom)
    len_a, len_b = la.safe_norm(da), la.safe_norm(db)
    inside = (s * len_a > tol) & ((1 - s) * len_a > tol) & (t * len_b > tol) & ((1 - t) * len_b > tol)
    mask = (jnp.abs(denom) > tol * jnp.maximum(len_a, len_b)) & inside
    pts = a + s[..., None] * da
    return pts.reshape(16, 2), mask.reshape(16)


def _first_two(points, mask):
    pos = jnp.cumsum(mask) - 1
    sel = ((pos[:, None] == jnp.arange(2)[None, :]) & mask[:, None]).astype(points.dtype)
    return sel.T @ points


def _manifold_point(corners1, corners2, n, tol):
    """Middle of the touching features along the axis ``n`` (from 2 into 1): vehicle 1's
    support toward -n, vehicle 2's toward +n, overlapped along the tangent."""
    t = jnp.stack([-n[1], n[0]])
    p1n, p2n = corners1 @ n, corners2 @ n
    p1t, p2t = corners1 @ t, corners2 @ t
    lo1, hi2 = jnp.min(p1n), jnp.max(p2n)
    s1 = p1n <= lo1 + tol
    s2 = p2n >= hi2 - tol
    big = jnp.asarray(1e30, corners1.dtype)
    lo = jnp.maximum(jnp.min(jnp.where(s1, p1t, big)), jnp.min(jnp.where(s2, p2t, big)))
    hi = jnp.minimum(jnp.max(jnp.where(s1, p1t, -big)), jnp.max(jnp.where(s2, p2t, -big)))
    return 0.5 * (lo1 + hi2) * n + 0.5 * (lo + hi) * t


def contact_geometry(vehicle1, state1, vehicle2, state2, coordinates=0.0) -> Contact2D:
    """The automatic contact of MODEL.md section 5 for the vehicles as they are in the given
    states (no motion): centroid of the footprints' overlap (z: middle of the vertical
    overlap) and the horizontal normal from vehicle 2 into vehicle 1. ``coordinates`` () m: how
    far from the origin the scene was given (``automatic_contact`` passes the states moved to
    the CGs' midpoint): the tolerances grow with it, so that edges the input's own rounding
    parts are still collinear."""
    dtype = state1.position.dtype
    c1, c2, n_sat, len_tol, solid, poly, count, area, centroid, manifold = _overlap(
        vehicle1, state1, vehicle2, state2, coordinates)
    xy = jnp.where(solid, centroid, manifold)

    pts, mask = outline_crossings(c1, c2, len_tol)
    two = _first_two(pts, mask)
    chord = two[1] - two[0]
    chord_len = la.safe_norm(chord)
    size = jnp.sqrt(vehicle1.length * vehicle1.width + vehicle2.length * vehicle2.width)
    crossing_ok = solid & (jnp.sum(mask) == 2) & (chord_len > jnp.sqrt(len_tol * size))
    n_line = jnp.stack([-chord[1], chord[0]]) / jnp.where(crossing_ok, chord_len, 1.0)
    toward1 = jnp.mean(c1, 0) - jnp.mean(c2, 0)  # footprint 2's centre -> footprint 1's
    side = jnp.where(n_line @ toward1 != 0, n_line @ toward1, n_line @ n_sat)
    n_line = jnp.where(side < 0, -n_line, n_line)
    n2 = jnp.where(crossing_ok, n_line, n_sat)

    point = jnp.stack([xy[0], xy[1], _vertical_middle(vehicle1, state1, vehicle2, state2)])
    normal = jnp.stack([n2[0], n2[1], jnp.zeros((), dtype)])
    return Contact2D(point, normal, poly, count, area, two, crossing_ok, solid)


def _overlap(vehicle1, state1, vehicle2, state2, coordinates):
    """What ``contact_geometry`` builds on: both footprints, the axis of least penetration, the
    length tolerance, whether the overlap is solid (wider than the length tolerance: its area
    above the tolerance times half its perimeter, the inradius of a triangle; the area's rounding
    is about the coordinates' rounding times the perimeter), the overlap polygon (vertices, count),
    its area and centroid, and the middle of the touching features (``_manifold_point``)."""
    c1 = footprint(vehicle1, state1.position[:2], state1.yaw)
    c2 = footprint(vehicle2, state2.position[:2], state2.yaw)
    n_sat, _ = least_penetration_normal(c1, c2, _axes(state1.yaw, state2.yaw))
    scale2 = vehicle1.length * vehicle1.width + vehicle2.length * vehicle2.width
    len_tol = 1e3 * jnp.finfo(state1.position.dtype).eps * jnp.maximum(jnp.sqrt(scale2), coordinates)
    poly, count = overlap_polygon(c1, c2)
    area, centroid = polygon_area_centroid(poly, count)
    idx, nxt = _next_index(count)
    perimeter = jnp.sum(jnp.where(idx < count, la.safe_norm(poly[nxt] - poly), 0.0))
    solid = area > 0.5 * len_tol * perimeter
    return c1, c2, n_sat, len_tol, solid, poly, count, area, centroid, _manifold_point(c1, c2, n_sat, len_tol)


@jax.custom_jvp
def _growing_overlap(penetration_time, probe):
    """0 (4,), whose derivative with respect to ``penetration_time`` is ``_overlap_growth(*probe)``
    (and 0 with respect to everything else). At the touch the overlap has no area and the centroid
    is the middle of the touching features; the first two components, added to it, give it the
    derivative of the growing overlap's centroid (for a corner entering a side: a triangle whose
    centroid is a third of the way in and spreads along the side, where the corner itself only goes
    in). The last two are the crushes' growth (at the touch both are 0, and AD of the distance to a
    box's faces from a corner averages the two faces that meet there)."""
    return jnp.zeros(4, probe[1].position.dtype)


@_growing_overlap.defjvp
def _growing_overlap_jvp(primals, tangents):
    penetration_time, probe = primals
    rate = jax.lax.stop_gradient(_overlap_growth(*probe))
    return jnp.zeros_like(rate), rate * tangents[0]


def _overlap_growth(vehicle1, state1, vehicle2, state2, t_i, t_x, coordinates, normal_pitch):
    """(4,): how fast, as the footprints (``state1``/``state2`` at t = 0, free motion) penetrate
    after touching at t_i, the overlap's area centroid moves away from the middle of the touching
    features (x, y; m/s), and the crushes grow (MODEL.md section 4, along the axis of least
    penetration tilted by ``normal_pitch``; m/s), measured at t_x (>= t_i). Each is its value at a
    probe instant at which the penetration has grown by sqrt(machine epsilon) of the vehicles' size
    (about 1e-7 m in float64, 3 mm in float32), divided by the time since t_i: all move linearly
    with that time while neither vehicle turns (the overlap of a corner and a side is a triangle of
    fixed shape, growing), so this is then the derivative to rounding; a turning vehicle adds an
    error of the order of the angle turned before the probe. 0 where the footprints are not closing."""
    _, closing = jax.jvp(lambda t: -separation(vehicle1, state1, vehicle2, state2, t), (t_x,), (jnp.ones_like(t_x),))
    size = jnp.sqrt(vehicle1.length * vehicle1.width + vehicle2.length * vehicle2.width)
    depth = jnp.sqrt(jnp.finfo(t_x.dtype).eps) * size
    grows = closing > 0
    t_probe = t_x + jnp.where(grows, depth / jnp.where(grows, closing, 1.0), 0.0)
    a1, a2 = advance(state1, t_probe), advance(state2, t_probe)
    _, _, n_sat, _, _, _, _, area, centroid, manifold = _overlap(vehicle1, a1, vehicle2, a2, coordinates)
    point = jnp.concatenate([centroid, _vertical_middle(vehicle1, a1, vehicle2, a2)[None]])
    n = tilt(jnp.concatenate([n_sat, jnp.zeros(1, n_sat.dtype)]), normal_pitch)
    crush = jnp.stack([derived.crush_depth(point, sign * n, a.position, la.rotation(a.yaw, a.pitch, a.roll), v)
                       for sign, a, v in ((-1.0, a1, vehicle1), (1.0, a2, vehicle2))])
    since = t_probe - t_i
    ok = grows & (area > 0) & (since > 0)
    return jnp.where(ok, jnp.concatenate([centroid - manifold, crush]) / jnp.where(ok, since, 1.0), 0.0)


def _vertical_middle(vehicle1, state1, vehicle2, state2):
    """() m: the middle of the boxes' vertical overlap (z of the automatic centroid)."""
    bottom = jnp.maximum(state1.position[2] - vehicle1.cg_height, state2.position[2] - vehicle2.cg_height)
    top = jnp.minimum(state1.position[2] - vehicle1.cg_height + vehicle1.height,
                      state2.position[2] - vehicle2.cg_height + vehicle2.height)
    return 0.5 * (bottom + top)


def tilt(normal, pitch):
    """Horizontal unit normal (3,) tilted up by ``pitch`` (rad): (cos p n_x, cos p n_y, sin p)."""
    cp = jnp.cos(pitch)
    return jnp.stack([cp * normal[0], cp * normal[1], jnp.sin(pitch) * jnp.ones_like(normal[0])])


# ---------------------------------------------------------------------------------------
# the entry point


class AutoContact(NamedTuple):
    """Everything automatic contact decides before the exchange (for plots and checks):
    time t_i () s, found () bool, states at the exchange instant, the contact used, the
    overlap geometry (``Contact2D``) at that instant, parted () bool: the footprints touched
    but are apart again at the exchange instant (a penetration_time longer than the touch),
    at_touch () bool: the exchange is at the touch itself (penetration_time 0, point and normal
    automatic), and touch_crush (2,) m: there, the crushes (0, with their derivative in
    penetration_time, which ``exchange_at_contact`` puts in place of the exchange's)."""

    time: jnp.ndarray
    found: jnp.ndarray
    state1: State
    state2: State
    contact: Contact
    geometry: Contact2D
    parted: jnp.ndarray
    at_touch: jnp.ndarray
    touch_crush: jnp.ndarray


def automatic_contact(vehicle1, state1, vehicle2, state2, contact, normal_pitch, *, auto_point, auto_normal):
    """Free motion to t_i + penetration_time and the contact there (MODEL.md section 5).

    ``contact.point`` (3,) m (global, at the exchange instant) is used where ``auto_point`` is
    False, ``contact.normal`` (3,) where ``auto_normal`` is False; ``normal_pitch`` () rad tilts
    the automatic normal. Returns an ``AutoContact``; where ``found`` is False the contact is a
    harmless separating one at t = 0 (see the module docstring)."""
    # the geometry about the CGs' midpoint: its tolerances (~1e-12 m) are below the rounding of
    # coordinates of 1e4 m and more, where the same scene gave another centroid and normal
    origin = (0.5 * (state1.position + state2.position)).at[2].set(0.0)
    near1, near2 = (s._replace(position=s.position - origin) for s in (state1, state2))
    t_i, found = first_contact(vehicle1, near1, vehicle2, near2)
    t_x = jnp.where(found, t_i + contact.penetration_time, 0.0)
    a1, a2 = advance(state1, t_x), advance(state2, t_x)
    geo = contact_geometry(vehicle1, advance(near1, t_x), vehicle2, advance(near2, t_x), la.safe_norm(origin))
    growth = _growing_overlap(contact.penetration_time, (vehicle1, near1, vehicle2, near2, t_i, t_x,
                                                         la.safe_norm(origin), normal_pitch))
    shift = jnp.where(geo.solid, 0.0, jnp.concatenate([growth[:2], jnp.zeros(1, growth.dtype)]))
    geo = geo._replace(point=geo.point + shift + origin, polygon=geo.polygon + origin[:2],
                       crossings=geo.crossings + origin[:2])
    point = jnp.where(auto_point, geo.point, contact.point)
    normal = jnp.where(auto_normal, tilt(geo.normal, normal_pitch), contact.normal)

    # never touching: an exchange that cannot happen (u.n >= 0), at the CGs' midpoint, t = 0
    mid = 0.5 * (state1.position + state2.position)
    u = (state1.velocity + la.cross(state1.angular_velocity, mid - state1.position)) - (
        state2.velocity + la.cross(state2.angular_velocity, mid - state2.position))
    u_len = la.safe_norm(u)
    x_axis = jnp.zeros(3, u.dtype).at[0].set(1.0)
    n_sep = jnp.where(u_len > 0, u / jnp.where(u_len > 0, u_len, 1.0), x_axis)
    contact = contact._replace(point=jnp.where(found, point, mid), normal=jnp.where(found, normal, n_sep))
    gap = separation(vehicle1, near1, vehicle2, near2, t_x)  # <= 0 at t_i itself, to rounding
    gap_tol = 1e3 * jnp.finfo(gap.dtype).eps * (_reach(vehicle1) + _reach(vehicle2) + la.safe_norm(origin))
    parted = found & (contact.penetration_time > 0) & (gap > gap_tol)
    at_touch = found & ~geo.solid & (contact.penetration_time == 0) & auto_point & auto_normal
    return AutoContact(jnp.where(found, t_i, HORIZON), found, a1, a2, contact, geo, parted, at_touch, growth[2:])


def automatic_exchange(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
                       normal_pitch, *, auto_point: bool, auto_normal: bool, smoothing=0.0) -> ExchangeResult:
    """The KS exchange at the automatic contact (MODEL.md sections 3-5).

    Vehicles (mass kg, inertia kg m^2, box m) and states (position m, velocity m/s, yaw rad,
    angular_velocity rad/s) are those of the case start; ``contact`` as for ``exchange``
    (restitution, friction, penetration_time s; point (3,) m and normal (3,) where not
    automatic); ``normal_pitch`` () rad. ``auto_point``/``auto_normal`` are static bools (they
    may also be traced bool arrays: the choice is a select, so one compiled program can serve
    rows with different user overrides).
    Returns ``ks_jax.exchange``'s result at t_i + penetration_time with ``contact.time`` = t_i
    (s); status "no_contact" and no NaN when the footprints do not touch within HORIZON.
    Pure and unbatched; works under ``jax.jit``, ``jax.vmap`` and ``jax.grad``.

    It is ``exchange_at_contact(automatic_stage(input_status(...)))``. A batched caller on CPU
    may run the three as separate jitted calls (``ks_jax.sweep`` and ``ks_jax.solve`` do): in one
    program XLA's fusion re-derives the status from every input inside each loop that reads a
    stand-in input (a sweep where no vehicle turns took 3x the time per point; benchmarks/RESULTS.md).
    Here the status is computed in a conditional of its own (``exchange.fence``), which keeps the
    one program (that of a fit's residuals) about the size of the three (tests/test_batch.py).
    """
    args = (vehicle1, state1, vehicle2, state2, contact)
    status = fence(input_status, *args)
    auto = automatic_stage(*args, normal_pitch, status, auto_point=auto_point, auto_normal=auto_normal)
    return exchange_at_contact(*args, status, auto, smoothing)


def automatic_stage(vehicle1, state1, vehicle2, state2, contact, normal_pitch, status, *, auto_point,
                    auto_normal) -> AutoContact:
    """``automatic_contact`` of a row whose ``input_status`` is ``status`` (() int32), run on harmless
    stand-in inputs where that is not OK. Its ``geometry`` is None (the exchange does not need it)."""
    ok = status == OK
    benign = _benign((vehicle1, state1, vehicle2, state2, contact), ok)
    normal_pitch = jnp.where(ok & jnp.isfinite(normal_pitch), normal_pitch, 0.0)
    auto = automatic_contact(*benign, normal_pitch, auto_point=auto_point, auto_normal=auto_normal)
    return auto._replace(geometry=None)


def exchange_at_contact(vehicle1, state1, vehicle2, state2, contact, status, auto: AutoContact,
                        smoothing=0.0) -> ExchangeResult:
    """The exchange at ``auto`` (``automatic_stage`` of the same inputs and ``status``), with the
    results of a row that never touches set as the module docstring says."""
    ok = status == OK
    pick = lambda new, old: jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, old)  # noqa: E731
    result = exchange(vehicle1, pick(auto.state1, state1), vehicle2, pick(auto.state2, state2),
                      pick(auto.contact, contact), smoothing)

    none = ok & ~auto.found
    c = result.contact
    towards1 = jnp.where(ok, state1.position - state2.position, 0.0)
    towards1 = towards1.at[2].set(0.0)
    length = la.safe_norm(towards1)
    x_axis = jnp.zeros(3, towards1.dtype).at[0].set(1.0)
    n_none = jnp.where(length > 0, towards1 / jnp.where(length > 0, length, 1.0), x_axis)
    c = c._replace(
        time=jnp.where(ok, auto.time, c.time),
        normal=jnp.where(none, n_none, c.normal),
        status=jnp.where(none, jnp.int32(NO_CONTACT), c.status),
    )
    touch = ok & auto.at_touch
    vehicles = tuple(v._replace(crush=jnp.where(none, 0.0, jnp.where(touch, auto.touch_crush[k], v.crush)),
                                ees=jnp.where(none, 0.0, v.ees))
                     for k, v in enumerate(result.vehicles))
    parted = ok & auto.found & auto.parted
    result = mask_invalid(ExchangeResult(c, vehicles), ~parted)
    return result._replace(contact=result.contact._replace(
        status=jnp.where(parted, jnp.int32(INVALID_PARTED), result.contact.status)))
