"""Where and how the footprints overlap: the impulse centroid and the contact plane of automatic
contact (docs/model.md, "Automatic contact").

Pure and unbatched, built from fixed-size arrays (an overlap polygon is (8, 2) with a vertex count).

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
- Normal: horizontal, pointing from vehicle 2 into vehicle 1, perpendicular to the contact plane,
  which is found from the two points where the outlines cross (``_plane_axis``):
  - both crossings on one edge of one footprint (a corner, or a whole face, entering a side or a
    face of the other: a T-bone, a corner into a side, a narrow front into a wide rear): the
    plane is that edge, and n its edge normal (the line through the crossings is that edge);
  - otherwise each crossing joins an edge of one footprint to a different edge of the other, and
    each footprint has a corner inside the other (an offset frontal, a rear-end with partial
    overlap, two corners meeting): the overlap is bounded by a face of each vehicle that face each
    other, and the line through the crossings is the overlap's diagonal, which no face lies
    along. n is the axis the faces first touched along (``contact_geometry``'s ``touched``: the
    axis of least penetration at the first touch, which ``automatic_contact`` passes), as the
    vehicles are turned now: for aligned vehicles the longitudinal axis, however deep.
  The sign of either axis: n points to the side where footprint 1's centre lies relative to
  footprint 2's (n . (c_1 - c_2) > 0; the axis of least penetration decides only if that product
  is exactly 0). It is then tilted up by ``normal_pitch``:
  n = (cos p n_x, cos p n_y, sin p). The axis of least penetration's own sign would not do: once
  a penetration is deeper than the overlap is wide, that axis turns across the plane, and its
  sign no longer says which way vehicle 1 lies (an inline rear-end came out "separating"). Nor
  would the CGs: a CG may sit anywhere along its box, and one 1 ft behind the front face is
  passed by the other's within a foot of penetration; the boxes' centres are passed only when
  the penetration is half a box long. Where the outlines do not cross in exactly two points more
  than ~1e-12 m inside both edges (collinear edges, also when rounding parts them by 1e-16 m;
  containment; a degenerate overlap) n is the axis of least penetration, with its own sign.
- Coordinates: the search and the geometry work about the CGs' midpoint, and the tolerances above
  (~1e3 machine epsilons of the vehicles' size) grow with the scene's distance from the origin, so
  that a scene given in survey coordinates (1e4-1e6 m) gives the contact of the same scene near the
  origin: its edges collinear within the input's own rounding stay collinear.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .. import linalg as la
from ..results import crush_depth
from .geometry import (
    advance,
    clip,
    cross2,
    edge_normals,
    footprint,
    is_solid,
    length_tolerance,
    penetrations,
    polygon_area_centroid,
    scene_size,
    separation,
    vertical_middle,
)

MAX_VERTICES = 8  # two convex quadrilaterals overlap in at most an octagon


class Contact2D(NamedTuple):
    """The automatic contact at one instant: point (3,) m, normal (3,) horizontal unit
    (from vehicle 2 into vehicle 1), overlap polygon (8, 2) m with ``count`` vertices,
    ``area`` () m^2, ``crossings`` (2, 2) m and ``crossing_ok`` () bool (the two outline
    crossings and whether the plane was found from them), ``facing`` () bool (they lie on
    different edges of both footprints, and the normal is the axis of least penetration, with the
    crossings' sign rule), ``solid`` () bool (the area is above its tolerance: the point is the
    area centroid, else the middle of the touching features)."""

    point: jnp.ndarray
    normal: jnp.ndarray
    polygon: jnp.ndarray
    count: jnp.ndarray
    area: jnp.ndarray
    crossings: jnp.ndarray
    crossing_ok: jnp.ndarray
    facing: jnp.ndarray
    solid: jnp.ndarray


# ---------------------------------------------------------------------------------------
# overlap polygon


def overlap_polygon(corners1, corners2):
    """Footprint 1 clipped by footprint 2 (both (4, 2), counter-clockwise): (8, 2) vertices, of
    which the first ``count`` () are used."""
    poly = jnp.zeros((MAX_VERTICES, 2), corners1.dtype).at[:4].set(corners1)

    def step(carry, edge):
        return clip(*carry, edge[0], edge[1]), None

    edges = jnp.stack([corners2, jnp.roll(corners2, -1, 0)], 1)  # (4, 2 ends, 2)
    (poly, count), _ = jax.lax.scan(step, (poly, jnp.int32(4)), edges)
    return poly, count


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
    denom = cross2(da, db)
    ab = b - a
    s = la.safe_div(cross2(ab, db), denom)
    t = la.safe_div(cross2(ab, da), denom)
    len_a, len_b = la.safe_norm(da), la.safe_norm(db)
    inside = (s * len_a > tol) & ((1 - s) * len_a > tol) & (t * len_b > tol) & ((1 - t) * len_b > tol)
    mask = (jnp.abs(denom) > tol * jnp.maximum(len_a, len_b)) & inside
    pts = a + s[..., None] * da
    return pts.reshape(16, 2), mask.reshape(16)


def _first_two(points, mask):
    pos = jnp.cumsum(mask) - 1
    sel = ((pos[:, None] == jnp.arange(2)[None, :]) & mask[:, None]).astype(points.dtype)
    return la.mm(sel.T, points)


# the axis (index into ``edge_normals``' rows) perpendicular to each edge of a footprint, edges as
# ``footprint``'s corners run: right side, front, left side, rear
_EDGE_AXIS_1 = (1, 0, 1, 0)
_EDGE_AXIS_2 = (3, 2, 3, 2)


def _plane_axis(mask, axes, n_sat):
    """The contact plane's normal axis (2,) (sign not yet chosen) from which edges the first two
    outline crossings lie on (``mask`` (16,) from ``outline_crossings``: edge i of footprint 1 x
    edge j of footprint 2 at 4 i + j), and ``facing`` () bool.

    Both crossings on one edge of one footprint: that edge's normal (``axes``, ``edge_normals``).
    Two crossings cannot share an edge of each footprint (two edges meet once; collinear ones do
    not count as crossing). Otherwise (``facing``) the chord joins two different edges of each
    footprint, the diagonal of an overlap bounded by a face of each vehicle, and the plane is
    taken across the axis of least penetration ``n_sat``."""
    pos = jnp.cumsum(mask) - 1
    first = (mask & (pos < 2)).reshape(4, 4)
    on1 = jnp.sum(first, 1) == 2  # (4,): both crossings on this edge of footprint 1
    on2 = jnp.sum(first, 0) == 2
    edge_axes = jnp.concatenate([axes[jnp.array(_EDGE_AXIS_1)], axes[jnp.array(_EDGE_AXIS_2)]])  # (8, 2)
    shared = jnp.concatenate([on1, on2])
    n_edge = jnp.sum(jnp.where(shared[:, None], edge_axes, 0.0), 0)
    facing = ~jnp.any(shared)
    return jnp.where(facing, n_sat, n_edge), facing


def _manifold_point(corners1, corners2, n, tol):
    """Middle of the touching features along the axis ``n`` (from 2 into 1): vehicle 1's
    support toward -n, vehicle 2's toward +n, overlapped along the tangent."""
    t = jnp.stack([-n[1], n[0]])
    p1n, p2n = la.mm(corners1, n), la.mm(corners2, n)
    p1t, p2t = la.mm(corners1, t), la.mm(corners2, t)
    lo1, hi2 = jnp.min(p1n), jnp.max(p2n)
    s1 = p1n <= lo1 + tol
    s2 = p2n >= hi2 - tol
    big = jnp.asarray(1e30, corners1.dtype)
    lo = jnp.maximum(jnp.min(jnp.where(s1, p1t, big)), jnp.min(jnp.where(s2, p2t, big)))
    hi = jnp.minimum(jnp.max(jnp.where(s1, p1t, -big)), jnp.max(jnp.where(s2, p2t, -big)))
    return 0.5 * (lo1 + hi2) * n + 0.5 * (lo + hi) * t


def contact_geometry(vehicle1, state1, vehicle2, state2, coordinates=0.0, touched=None) -> Contact2D:
    """The automatic contact of docs/model.md, "Automatic contact" for the vehicles as they are in the given
    states (no motion): centroid of the footprints' overlap (z: middle of the vertical
    overlap) and the horizontal normal from vehicle 2 into vehicle 1. ``coordinates`` () m: how
    far from the origin the scene was given (``automatic_contact`` passes the states moved to
    the CGs' midpoint): the tolerances grow with it, so that edges the input's own rounding
    parts are still collinear. ``touched``: () int, which of the four edge normals (``edge_normals``:
    vehicle 1's x and y, vehicle 2's x and y) was the axis of least penetration at the first touch; where
    the faces facing each other decide the normal, it is that axis as the vehicles are turned now, not
    the axis of least penetration now, which turns across once the penetration is deeper than the
    overlap is wide. None: the axis of least penetration now."""
    dtype = state1.position.dtype
    c1, c2, n_sat, len_tol, solid, poly, count, area, centroid, manifold = _overlap(
        vehicle1, state1, vehicle2, state2, coordinates)
    xy = jnp.where(solid, centroid, manifold)

    pts, mask = outline_crossings(c1, c2, len_tol)
    two = _first_two(pts, mask)
    chord_len = la.safe_norm(two[1] - two[0])
    size = scene_size(vehicle1, vehicle2)
    crossing_ok = solid & (jnp.sum(mask) == 2) & (chord_len > jnp.sqrt(len_tol * size))
    normals = edge_normals(state1.yaw, state2.yaw)
    axis, facing = _plane_axis(mask, normals, n_sat if touched is None else normals[touched])
    toward1 = jnp.mean(c1, 0) - jnp.mean(c2, 0)  # footprint 2's centre -> footprint 1's
    along = la.mm(axis, toward1)
    side = jnp.where(along != 0, along, la.mm(axis, n_sat))
    axis = jnp.where(side < 0, -axis, axis)
    n2 = jnp.where(crossing_ok, axis, n_sat)

    point = jnp.stack([xy[0], xy[1], vertical_middle(vehicle1, state1, vehicle2, state2)])
    normal = jnp.stack([n2[0], n2[1], jnp.zeros((), dtype)])
    return Contact2D(point, normal, poly, count, area, two, crossing_ok, crossing_ok & facing, solid)


def _least_penetration_normal(corners1, corners2, axes):
    """(2,) unit axis of least penetration, from vehicle 2 into vehicle 1 (or, when apart, the
    most separating axis, pointing the same way), and the penetration depth () m."""
    pen = penetrations(corners1, corners2, axes)
    k = jnp.argmin(pen)
    sign = jnp.where(k < 4, 1.0, -1.0)
    return sign * axes[k % 4], pen[k]


def _overlap(vehicle1, state1, vehicle2, state2, coordinates):
    """What ``contact_geometry`` builds on: both footprints, the axis of least penetration, the
    length tolerance, whether the overlap is solid (wider than the length tolerance: its area
    above the tolerance times half its perimeter, the inradius of a triangle; the area's rounding
    is about the coordinates' rounding times the perimeter), the overlap polygon (vertices, count),
    its area and centroid, and the middle of the touching features (``_manifold_point``)."""
    c1 = footprint(vehicle1, state1.position[:2], state1.yaw)
    c2 = footprint(vehicle2, state2.position[:2], state2.yaw)
    n_sat, _ = _least_penetration_normal(c1, c2, edge_normals(state1.yaw, state2.yaw))
    len_tol = length_tolerance(vehicle1, vehicle2, state1.position.dtype, coordinates)
    poly, count = overlap_polygon(c1, c2)
    area, centroid = polygon_area_centroid(poly, count)
    solid = is_solid(poly, count, area, len_tol)
    return c1, c2, n_sat, len_tol, solid, poly, count, area, centroid, _manifold_point(c1, c2, n_sat, len_tol)


@jax.custom_jvp
def growing_overlap(penetration_time, probe):
    """0 (4,), whose derivative with respect to ``penetration_time`` is ``_overlap_growth(*probe)``
    (and 0 with respect to everything else). At the touch the overlap has no area and the centroid
    is the middle of the touching features; the first two components, added to it, give it the
    derivative of the growing overlap's centroid (for a corner entering a side: a triangle whose
    centroid is a third of the way in and spreads along the side, where the corner itself only goes
    in). The last two are the crushes' growth (at the touch both are 0, and AD of the distance to a
    box's faces from a corner averages the two faces that meet there)."""
    return jnp.zeros(4, probe[1].position.dtype)


@growing_overlap.defjvp
def _growing_overlap_jvp(primals, tangents):
    penetration_time, probe = primals
    rate = jax.lax.stop_gradient(_overlap_growth(*probe))
    return jnp.zeros_like(rate), rate * tangents[0]


def _overlap_growth(vehicle1, state1, vehicle2, state2, t_i, t_x, coordinates, normal_pitch):
    """(4,): how fast, as the footprints (``state1``/``state2`` at t = 0, free motion) penetrate
    after touching at t_i, the overlap's area centroid moves away from the middle of the touching
    features (x, y; m/s), and the crushes grow (along the axis of least
    penetration tilted by ``normal_pitch``; m/s), measured at t_x (>= t_i). Each is its value at a
    probe instant at which the penetration has grown by sqrt(machine epsilon) of the vehicles' size
    (about 1e-7 m in float64, 3 mm in float32), divided by the time since t_i: all move linearly
    with that time while neither vehicle turns (the overlap of a corner and a side is a triangle of
    fixed shape, growing), so this is then the derivative to rounding; a turning vehicle adds an
    error of the order of the angle turned before the probe. 0 where the footprints are not closing."""
    _, closing = jax.jvp(lambda t: -separation(vehicle1, state1, vehicle2, state2, t), (t_x,), (jnp.ones_like(t_x),))
    size = scene_size(vehicle1, vehicle2)
    depth = jnp.sqrt(jnp.finfo(t_x.dtype).eps) * size
    grows = closing > 0
    t_probe = t_x + jnp.where(grows, depth / jnp.where(grows, closing, 1.0), 0.0)
    a1, a2 = advance(state1, t_probe), advance(state2, t_probe)
    _, _, n_sat, _, _, _, _, area, centroid, manifold = _overlap(vehicle1, a1, vehicle2, a2, coordinates)
    point = jnp.concatenate([centroid, vertical_middle(vehicle1, a1, vehicle2, a2)[None]])
    n = tilt(jnp.concatenate([n_sat, jnp.zeros(1, n_sat.dtype)]), normal_pitch)
    crush = jnp.stack([crush_depth(point, sign * n, a.position, la.rotation(a.yaw, a.pitch, a.roll), v)
                       for sign, a, v in ((-1.0, a1, vehicle1), (1.0, a2, vehicle2))])
    since = t_probe - t_i
    ok = grows & (area > 0) & (since > 0)
    return jnp.where(ok, jnp.concatenate([centroid - manifold, crush]) / jnp.where(ok, since, 1.0), 0.0)


def tilt(normal, pitch):
    """Horizontal unit normal (3,) tilted up by ``pitch`` (rad): (cos p n_x, cos p n_y, sin p)."""
    sp, cp = la.sincos(jnp.asarray(pitch, jnp.result_type(pitch, normal)))  # a Python pitch: the normal's dtype
    return jnp.stack([cp * normal[0], cp * normal[1], sp * jnp.ones_like(normal[0])])
