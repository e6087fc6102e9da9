"""The plane geometry that automatic contact's modules share (docs/model.md, "Automatic contact"):
footprints and their free motion, the separation of two footprints, the scene's sizes and
tolerances, and convex polygons (clipping, area and centroid).

Pure and unbatched, built from fixed-size arrays (a footprint is (4, 2); a polygon has a fixed
number of rows, of which the first ``count`` are its vertices), so it works under ``jax.jit``,
``jax.vmap`` and ``jax.grad``.

- Footprint: the bounding box seen from above, x in [cg_to_front - length, cg_to_front],
  y in [-width/2, width/2] in the body frame, turned by the yaw only (pitch and roll are
  ignored for the footprint and the vertical overlap).
- Free motion: the CG moves with its constant velocity (3D, so z too); the body turns about
  its CG at the constant yaw rate (z component of the global angular velocity). Pitch and roll
  stay as given; velocities and angular velocities are unchanged.
"""

from __future__ import annotations

import jax.numpy as jnp

from .. import linalg as la
from ..checks import is_fixed
from ..types import State, Vehicle

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
    s, c = la.sincos(yaw)
    return jnp.stack([xy[0] + c * bx - s * by, xy[1] + s * bx + c * by], -1)


def advance(state: State, t) -> State:
    """The state after free motion for ``t`` s: CG moved by velocity * t, yaw turned by the yaw
    rate * t; everything else unchanged."""
    return state._replace(position=state.position + state.velocity * t,
                          yaw=state.yaw + state.angular_velocity[2] * t)


def footprint_at(vehicle, state, t):
    """``footprint`` after free motion for ``t`` s from ``state``."""
    return footprint(vehicle, state.position[:2] + state.velocity[:2] * t, state.yaw + state.angular_velocity[2] * t)


def edge_normals(yaw1, yaw2):
    """(4, 2) unit edge normals of both footprints."""
    (s1, c1), (s2, c2) = la.sincos(yaw1), la.sincos(yaw2)
    return jnp.stack([jnp.stack([c1, s1]), jnp.stack([-s1, c1]), jnp.stack([c2, s2]), jnp.stack([-s2, c2])])


def penetrations(corners1, corners2, axes):
    """(8,) overlap of the projections on each axis, for vehicle 1 on the + side of vehicle 2
    (first 4) and on the - side (last 4). All >= 0 iff the footprints touch."""
    p1 = la.mm(corners1, axes.T)  # (4 corners, 4 axes)
    p2 = la.mm(corners2, axes.T)
    plus = jnp.max(p2, 0) - jnp.min(p1, 0)
    minus = jnp.max(p1, 0) - jnp.min(p2, 0)
    return jnp.concatenate([plus, minus])


def separation(vehicle1, state1, vehicle2, state2, t):
    """s(t) () m: the largest gap between the footprints' projections on their edge normals at
    time t of free motion; > 0 apart, <= 0 touching or overlapping."""
    c1 = footprint_at(vehicle1, state1, t)
    c2 = footprint_at(vehicle2, state2, t)
    axes = edge_normals(state1.yaw + state1.angular_velocity[2] * t, state2.yaw + state2.angular_velocity[2] * t)
    return -jnp.min(penetrations(c1, c2, axes))


# ---------------------------------------------------------------------------------------
# sizes and tolerances


def reach(vehicle):
    """() m: the radius about the CG of the circle that holds the footprint at any yaw."""
    far = jnp.maximum(jnp.abs(vehicle.cg_to_front), jnp.abs(vehicle.cg_to_front - vehicle.length))
    return jnp.sqrt(far * far + 0.25 * vehicle.width * vehicle.width)


def scene_size(vehicle1, vehicle2):
    """() m: the size the geometry's tolerances are scaled by, sqrt(L_1 W_1 + L_2 W_2), leaving out a fixed
    object (``checks.is_fixed``): a wall is a box kilometres long (``case.fixed``), whose size would make
    the tolerances of a float32 scene metres wide, where its edges near the vehicle are as exact as a
    vehicle's."""
    area2 = jnp.where(is_fixed(vehicle2), 0.0, vehicle2.length * vehicle2.width)
    return jnp.sqrt(vehicle1.length * vehicle1.width + area2)


def length_tolerance(vehicle1, vehicle2, dtype, coordinates):
    """() m: ~1e3 machine epsilons of the scene's size (``scene_size``) or of its distance from
    the origin, whichever is larger: the width below which an overlap has no area, and how far apart two
    features may be and still count as one."""
    return 1e3 * jnp.finfo(dtype).eps * jnp.maximum(scene_size(vehicle1, vehicle2), coordinates)


def vertical_middle(vehicle1, state1, vehicle2, state2):
    """() m: the middle of the boxes' vertical overlap (z of the automatic centroid)."""
    bottom = jnp.maximum(state1.position[2] - vehicle1.cg_height, state2.position[2] - vehicle2.cg_height)
    top = jnp.minimum(state1.position[2] - vehicle1.cg_height + vehicle1.height,
                      state2.position[2] - vehicle2.cg_height + vehicle2.height)
    return 0.5 * (bottom + top)


# ---------------------------------------------------------------------------------------
# convex polygons


def cross2(a, b):
    """The z component of the cross product of 2-vectors (the last axis)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _next_index(count, size):
    """(size,) row indices and each row's successor among the first ``count`` (the last wraps to 0)."""
    idx = jnp.arange(size)
    return idx, jnp.where(idx + 1 < count, idx + 1, 0)


def clip(poly, count, a, b):
    """Clip the convex polygon (k, 2) with ``count`` vertices (k of room: 8 for two boxes) by the
    half-plane left of the directed line a -> b (Sutherland-Hodgman step). Returns (poly, count)."""
    size = poly.shape[0]
    idx, nxt = _next_index(count, size)
    valid = idx < count
    q = poly[nxt]
    edge = b - a
    d0 = cross2(edge, poly - a)
    d1 = cross2(edge, q - a)
    in0, in1 = d0 >= 0, d1 >= 0
    crossing = valid & (in0 != in1)
    s = la.safe_div(d0, d0 - d1)
    x = poly + s[:, None] * (q - poly)
    cand = jnp.stack([poly, x], 1).reshape(2 * size, 2)
    keep = jnp.stack([valid & in0, crossing], 1).reshape(2 * size)
    pos = jnp.cumsum(keep) - 1
    onehot = ((pos[:, None] == jnp.arange(size)[None, :]) & keep[:, None]).astype(poly.dtype)
    return la.mm(onehot.T, cand), jnp.minimum(jnp.sum(keep), size).astype(jnp.int32)


def polygon_area_centroid(poly, count):
    """Area () m^2 and area centroid (2,) m of the polygon's first ``count`` vertices (the
    vertex mean where the area is 0)."""
    idx, nxt = _next_index(count, poly.shape[0])
    valid = idx < count
    w = jnp.where(valid[:, None], poly, 0.0)
    origin = jnp.sum(w, 0) / jnp.maximum(count, 1)
    p = jnp.where(valid[:, None], poly - origin, 0.0)
    q = p[nxt]
    cr = jnp.where(valid, cross2(p, q), 0.0)
    area = 0.5 * jnp.sum(cr)
    moment = jnp.sum((p + q) * cr[:, None], 0) / 6.0
    return area, origin + jnp.stack([la.safe_div(moment[0], area), la.safe_div(moment[1], area)])


def is_solid(poly, count, area, len_tol):
    """() bool: the polygon (its first ``count`` vertices, of area ``area``) is wider than ``len_tol``: its
    area above the tolerance times half its perimeter (the inradius of a triangle; the area's rounding is
    about the coordinates' rounding times the perimeter)."""
    idx, nxt = _next_index(count, poly.shape[0])
    perimeter = jnp.sum(jnp.where(idx < count, la.safe_norm(poly[nxt] - poly), 0.0))
    return area > 0.5 * len_tol * perimeter
