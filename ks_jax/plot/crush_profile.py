"""Each vehicle's measured crush profile (docs/model.md, "Crush energy"), drawn to scale in the top view on its
damaged side, where the vehicle is at the first exchange: the undeformed face, and the crushed outline C1 .. Cn set
in from it, the damage centred on the exchange's centroid (as far as the face allows).

The side is the profile's ``side`` where the case names it, else the face of the vehicle's box nearest the centroid
of the first exchange it takes part in. C1 is at the left end of the front or the rear and at the front end of a side
(the profile's order does not change its energy). matplotlib is imported only inside ``draw_profiles``.
"""

from __future__ import annotations

import math

import numpy as np

from ..case import Case

# per side: the face's outward normal in the body frame (ISO: x forward, y left) and the direction from C1 to Cn
FACES = {"front": ((1.0, 0.0), (0.0, -1.0)), "rear": ((-1.0, 0.0), (0.0, -1.0)),
         "left": ((0.0, 1.0), (-1.0, 0.0)), "right": ((0.0, -1.0), (-1.0, 0.0))}


def _half_sizes(vehicle):
    """The box's centre in the body frame (x, 0) and its half length and width, m."""
    length, width, front = float(vehicle.length), float(vehicle.width), float(vehicle.cg_to_front)
    return np.array([front - 0.5 * length, 0.0]), np.array([0.5 * length, 0.5 * width])


def damaged_side(vehicle, cg, yaw, point) -> str:
    """The side ("front", "rear", "left", "right") of ``vehicle``'s box (its inputs; CG ``cg`` (2,), ``yaw`` rad)
    nearest the global ``point`` (2,)."""
    c, s = math.cos(yaw), math.sin(yaw)
    d = np.asarray(point, float)[:2] - np.asarray(cg, float)[:2]
    local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
    centre, half = _half_sizes(vehicle)
    gaps = {side: abs(half @ np.abs(normal) - (local - centre) @ np.asarray(normal))
            for side, (normal, _) in FACES.items()}
    return min(gaps, key=gaps.get)


def profile_outline(vehicle, cg, yaw, profile, side, point=None):
    """(face, crushed): global points (2, 2) of the damaged stretch of the undeformed face, from C1's end to Cn's,
    and (n, 2) of the crushed outline, each depth set in from the face. The stretch (the profile's width, at most the
    face's length) is centred on ``point``'s foot on the face where given, else on the face's middle."""
    normal, along = (np.asarray(v) for v in FACES[side])
    centre, half = _half_sizes(vehicle)
    face_middle = centre + normal * (half @ np.abs(normal))
    reach = half @ np.abs(along)  # half the face's length
    width = min(float(profile.width), 2.0 * reach)
    c, s = math.cos(yaw), math.sin(yaw)
    turn = np.array([[c, -s], [s, c]])
    middle = 0.0
    if point is not None:
        d = np.asarray(point, float)[:2] - np.asarray(cg, float)[:2]
        middle = float((turn.T @ d - face_middle) @ along)
    middle = min(max(middle, -reach + 0.5 * width), reach - 0.5 * width)
    n = len(profile.depths)
    offsets = middle + width * (np.arange(n) / (n - 1) - 0.5)
    local_face = face_middle + offsets[:, None] * along
    local_crushed = local_face - np.asarray(profile.depths)[:, None] * normal
    to_global = lambda pts: np.asarray(cg, float)[:2] + pts @ turn.T  # noqa: E731
    return to_global(local_face[[0, -1]]), to_global(local_crushed)


def _centroid_of(case: Case, vehicle: int, exchanges: list):
    """The centroid (2,) of the first exchange ``vehicle`` takes part in (``Solution.exchange_list``), or None."""
    entry = case.body_entry(vehicle)
    for ex in exchanges:
        if entry in ex["between"] and ex["point"] is not None and np.all(np.isfinite(ex["point"])):
            return np.asarray(ex["point"], float)[:2]
    return None


def draw_profiles(ax, case: Case, exchanges: list, cgs, yaws, colors, names):
    """Every vehicle's measured crush profile on ``ax``, at its place at the first exchange (``cgs``, ``yaws``): the
    crushed outline, filled to the undeformed face, in the vehicle's colour (``colors``), named in the legend."""
    from matplotlib.patches import Polygon

    for i, profile in enumerate(case.crush):
        if profile is None:
            continue
        vehicle = case.inputs.vehicles[i]
        point = _centroid_of(case, i, exchanges)
        side = profile.side or (damaged_side(vehicle, cgs[i], yaws[i], point) if point is not None else None)
        if side is None:
            continue
        face, crushed = profile_outline(vehicle, cgs[i], yaws[i], profile, side, point)
        shape = np.vstack([face[:1], crushed, face[1:]])
        ax.add_patch(Polygon(shape, closed=True, facecolor=colors[i], edgecolor="none", alpha=0.25, zorder=3.5))
        ax.plot(crushed[:, 0], crushed[:, 1], "-o", color=colors[i], lw=1.6, ms=2.5, zorder=3.6,
                gid=f"crush-profile-{i}", label=f"{names[i]}: measured crush profile ({side}, to scale)")
