"""A body's footprint as the top view draws it: its corners from its size, CG and yaw, its outline with the front
face thicker, its colour, and the overlap of two footprints (``clip_polygon``). NumPy and matplotlib only."""

from __future__ import annotations

import math

import numpy as np

COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "magenta")


def footprint_box(length, width, cg_to_front, xy, yaw):
    """(4, 2) m: the corners of a footprint ``length`` by ``width`` whose front is ``cg_to_front`` ahead of its CG at
    ``xy``, turned by ``yaw`` (rad): rear right, front right, front left, rear left (corners 1-2 the front face)."""
    a, b, h = cg_to_front - length, cg_to_front, 0.5 * width
    body = np.array([[a, -h], [b, -h], [b, h], [a, h]])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.asarray(xy)[:2] + body @ np.array([[c, s], [-s, c]])


def clip_polygon(subject, clip):
    """Sutherland-Hodgman in NumPy: convex ``subject`` (k, 2) clipped by the counter-clockwise
    convex polygon ``clip`` (m, 2). Returns (j, 2) (j may be 0)."""
    out = [np.asarray(p, float) for p in subject]
    for i in range(len(clip)):
        a, b = np.asarray(clip[i], float), np.asarray(clip[(i + 1) % len(clip)], float)
        e = b - a
        side = lambda p: e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])  # noqa: E731
        pts, out = out, []
        for k, p in enumerate(pts):
            q = pts[(k + 1) % len(pts)]
            dp, dq = side(p), side(q)
            if dp >= 0:
                out.append(p)
            if (dp >= 0) != (dq >= 0):
                out.append(p + dp / (dp - dq) * (q - p))
        if not out:
            break
    return np.array(out).reshape(-1, 2)


def vehicle_color(i):
    """Vehicle ``i``'s colour (``COLORS``; a case has at most as many vehicles as there are colours)."""
    return COLORS[i % len(COLORS)]


def draw_footprint(ax, corners, color, style, label=None, alpha=1.0, lw=1.4, gid=None):
    """A footprint: its closed outline (``gid`` on it) and its front face (corners 1-2) drawn thicker."""
    closed = np.vstack([corners, corners[:1]])
    ax.plot(closed[:, 0], closed[:, 1], style, color=color, lw=lw, label=label, alpha=alpha, gid=gid)
    ax.plot(corners[1:3, 0], corners[1:3, 1], style, color=color, lw=lw * 15 / 7, alpha=alpha)  # front face
