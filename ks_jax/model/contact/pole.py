"""A pole struck by a vehicle (docs/model.md, "Fixed objects"): automatic contact with a disc instead of a box.

The pole is vehicle 2 of the exchange, at rest, its footprint the disc of diameter ``vehicle2.width`` about its
position (its box, the square about the disc, only bounds it: ``geometry.reach``).

- ``disc_gap``: the signed distance from the disc to the vehicle's footprint at a time of free motion (> 0
  apart, 0 touching, < 0 overlapping): the separation function that ``search.first_contact`` searches for a root.
- ``disc_contact``: the contact of a footprint overlapping the disc. The overlap is the disc, as the polygon
  of ``SIDES`` sides inscribed in it (within 0.5 % of its radius, and never past the circle, so that at the
  touch the search finds there is no overlap yet), clipped by the footprint's four sides; the centroid is
  its area centroid. The normal is radial, from the pole's centre towards that centroid (the contact plane is
  the tangent there), pointing from the pole into the vehicle. Where the centroid is within ``CENTRED``
  radii of the centre (the pole wholly inside the footprint), the normal is that of the side the pole came in
  through, turned inwards: the footprint's side the centre lay farthest beyond at the first touch. Where the
  overlap has no area (the instant of touching), the centroid is the footprint's point nearest the centre,
  and the normal radial.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .. import linalg as la
from .geometry import clip, is_solid, polygon_area_centroid

SIDES = 32
CENTRED = 1e-3  # radii: a centroid this near the centre gives no radial direction to speak of
_ANGLES = np.arange(SIDES) * (2 * math.pi / SIDES)
_RING = np.stack([np.cos(_ANGLES), np.sin(_ANGLES)], -1)  # (SIDES, 2): the unit circle's polygon, constants


def _body(vehicle, xy, yaw, point):
    """``point`` (2,) in the footprint's frame, and the footprint's extent: (p, (a, b, h))."""
    s, c = la.sincos(yaw)
    d = point - xy
    p = jnp.stack([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
    return p, (vehicle.cg_to_front - vehicle.length, vehicle.cg_to_front, 0.5 * vehicle.width)


def _signed_distance(p, box):
    """Signed distance (m) from ``p`` (body frame) to the box [a, b] x [-h, h]: > 0 outside, < 0 inside; and
    the box's point nearest ``p`` (body frame)."""
    a, b, h = box
    q = jnp.stack([jnp.clip(p[0], a, b), jnp.clip(p[1], -h, h)])
    outside = la.safe_norm(p - q)
    depth = jnp.minimum(jnp.minimum(p[0] - a, b - p[0]), jnp.minimum(p[1] + h, h - p[1]))
    return jnp.where(depth > 0, -depth, outside), q


def disc_gap(vehicle1, state1, vehicle2, state2, t):
    """() m: the signed distance from the pole (vehicle 2: the disc of diameter ``vehicle2.width`` about its
    CG) to the footprint of vehicle 1 after free motion for ``t`` s (> 0 apart, <= 0 touching or
    overlapping): ``geometry.separation`` for a pole."""
    xy = state1.position[:2] + state1.velocity[:2] * t
    yaw = state1.yaw + state1.angular_velocity[2] * t
    centre = state2.position[:2] + state2.velocity[:2] * t
    p, box = _body(vehicle1, xy, yaw, centre)
    return _signed_distance(p, box)[0] - 0.5 * vehicle2.width


def disc_polygon(centre, radius, corners):
    """The disc as the regular polygon of ``SIDES`` sides inscribed in it, clipped by the footprint
    (``corners`` (4, 2), counter-clockwise): ((SIDES + 4, 2) vertices, of which the first ``count``)."""
    ring = centre + radius * jnp.asarray(_RING, corners.dtype)
    poly = jnp.zeros((SIDES + 4, 2), corners.dtype).at[:SIDES].set(ring)
    count = jnp.int32(SIDES)
    for k in range(4):
        poly, count = clip(poly, count, corners[k], corners[(k + 1) % 4])
    return poly, count


def disc_contact(vehicle1, state1, centre, radius, corners1, len_tol, touch_state, touch_centre):
    """(point (2,), normal (2,) from the pole into the vehicle, polygon, count, area, solid) of the footprint
    of ``vehicle1`` in ``state1`` (corners ``corners1``) against the disc; ``len_tol`` (m): below this width
    the overlap has no area (``geometry.is_solid``). ``touch_state``, ``touch_centre``: the vehicle and
    the pole's centre at the first touch (for a pole wholly inside the footprint: the side it came in by)."""
    poly, count = disc_polygon(centre, radius, corners1)
    area, centroid = polygon_area_centroid(poly, count)
    solid = is_solid(poly, count, area, len_tol)

    p, box = _body(vehicle1, state1.position[:2], state1.yaw, centre)
    _, nearest = _signed_distance(p, box)
    s, c = la.sincos(state1.yaw)
    to_world = lambda v: jnp.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])  # noqa: E731
    touch = state1.position[:2] + to_world(nearest)  # the footprint's point nearest the centre
    point = jnp.where(solid, centroid, touch)

    radial = point - centre
    length = la.safe_norm(radial)
    centred = length <= CENTRED * radius
    q, (a, b, h) = _body(vehicle1, touch_state.position[:2], touch_state.yaw, touch_centre)
    gaps = jnp.stack([q[0] - a, b - q[0], q[1] + h, h - q[1]])  # inside the rear, front, right and left sides
    inward = jnp.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]], p.dtype)[jnp.argmin(gaps)]
    normal = jnp.where(centred, to_world(inward), radial / jnp.where(centred, 1.0, length))
    return point, normal, poly, count, area, solid
