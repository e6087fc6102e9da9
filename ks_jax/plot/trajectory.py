"""What the top view draws of each vehicle's way before and after the first exchange: its approach, its path to
rest, its hitches and its measured rest position (``top_view``'s docstring says what each looks like). The paths
are ``ks_jax.solve.cases.trajectories``, every step of the motions. NumPy and matplotlib only."""

from __future__ import annotations

import math

import numpy as np

from .. import units as U
from ..case import visible
from ..case.paths import canonical_path
from .outline import draw_footprint, footprint_box, vehicle_color

PATH_OUTLINES = 8  # outlines drawn on the way from the exchange to rest, between the two drawn solid
PHASE_LABEL = 7.0  # points from a phase's start marker to its time's text, across the vehicle's heading


def draw_motion_to_rest(ax, solution, count, paths):
    """The path of each of the ``count`` vehicles from the exchange to rest (``paths``: ``Trajectories.rest``, every
    step of the motion): the CG's path, ``PATH_OUTLINES`` faded outlines at instants evenly
    spaced in time (each at the step nearest it, so that it sits on the path), and the outline at rest, placed by the
    results (``rest_position``, ``rest_yaw``) where the path's last step is."""
    from matplotlib.patches import Polygon

    names, inputs = [visible(n) for n in solution.case.vehicle_names], solution.case.inputs
    for i in range(count):
        rest, path = solution.result.rest[i], paths[i]
        if rest is None or path is None:
            continue
        v = inputs.vehicles[i]
        size = (float(v.length), float(v.width), float(v.cg_to_front))
        t, d = float(rest.time_to_rest), float(rest.distance_to_rest)
        step = t / (PATH_OUTLINES + 1)
        ax.plot(path[:, 1], path[:, 2], "-", color=vehicle_color(i), lw=0.9, gid=f"rest-path-{i}",
                label=f"{names[i]}: CG path to rest, {d:.2f} m ({d / U.FT:.1f} ft) in {t:.2f} s; "
                      f"outlines every {step:.2f} s")
        if step > 0:
            instants = step * np.arange(1, PATH_OUTLINES + 1)
            for k in np.unique(np.clip(np.searchsorted(path[:, 0], instants), 1, len(path) - 1)):
                draw_footprint(ax, footprint_box(*size, path[k, 1:3], path[k, 3]), vehicle_color(i), "-", alpha=0.3,
                               lw=0.6, gid=f"path-outline-{i}")
        xy = np.asarray(rest.rest_position, float)
        yaw = float(rest.rest_yaw)
        corners = footprint_box(*size, xy, math.radians(yaw))
        where = "at rest" if bool(rest.at_rest) else f"at the time limit, {t:.2f} s (not at rest)"
        ax.add_patch(Polygon(corners, closed=True, facecolor=vehicle_color(i), edgecolor="none", alpha=0.15))
        draw_footprint(ax, corners, vehicle_color(i), "-", gid=f"rest-outline-{i}",
                       label=f"{names[i]} {where}: CG ({xy[0]:.2f}, {xy[1]:.2f}) m, yaw {yaw:.1f} deg "
                             f"(turned {float(rest.rotation_to_rest):+.1f} deg)")
        ax.plot(*xy, "o", color=vehicle_color(i), ms=5, mec="black", mew=0.6, gid=f"rest-cg-{i}")


def draw_approaches(ax, solution, scene, paths):
    """Each vehicle's approach (``solution.result.approach``; ``paths``: ``Trajectories.approach``, its CG's path,
    every step), drawn as the start of its trajectory: the CG's path from the
    approach's start to the impact (dashed, as thin as its path to rest, which goes on from the exchange; with
    automatic contact the free motion from the case state to the CG at the first exchange, ``scene.cgs``, is added,
    so that the two join), a small open circle at the start of each phase (its position in the results) with the
    phase's start time beside it (across the heading, on alternate sides from one phase to the next, so that the
    times of short phases do not print over each other), and the outline at the approach's start (thin, faded). One
    legend entry for every approach."""
    label = "approach (CG path before the impact; marks at each phase's start)"
    text = dict(textcoords="offset points", fontsize=6, zorder=7,
                bbox=dict(boxstyle="round,pad=0.1", facecolor="white", edgecolor="none", alpha=0.6))
    for i in range(scene.count):
        found, path = solution.result.approach[i], paths[i]
        if found is None or path is None:
            continue
        xy = np.asarray(path, float)[:, 1:3]
        starts = np.asarray(found.position, float).reshape(-1, 2)
        if not (np.all(np.isfinite(xy)) and np.all(np.isfinite(starts))):  # a phase that breaks a rule: NaN
            continue
        if np.linalg.norm(scene.cgs[i] - xy[-1]) > 0:  # automatic contact: moved freely on to the exchange
            xy = np.vstack([xy, scene.cgs[i]])
        color = vehicle_color(i)
        ax.plot(xy[:, 0], xy[:, 1], "--", color=color, lw=0.9, gid=f"approach-path-{i}")
        times, yaws = np.asarray(found.time, float).reshape(-1), np.asarray(found.yaw, float).reshape(-1)
        for k, (point, t, yaw) in enumerate(zip(starts, times, yaws)):
            ax.plot(*point, "o", ms=4, mfc="white", mec=color, mew=1.0, zorder=6, gid=f"approach-phase-{i}-{k}")
            side = math.radians(yaw) + (0.5 * math.pi if k % 2 == 0 else -0.5 * math.pi)  # left, then right
            off = np.array([math.cos(side), math.sin(side)])
            ax.annotate(f"{t:.2f} s", point, xytext=tuple(PHASE_LABEL * off), color=color, gid=f"approach-time-{i}-{k}",
                        ha="left" if off[0] > 0.3 else "right" if off[0] < -0.3 else "center",
                        va="bottom" if off[1] > 0.3 else "top" if off[1] < -0.3 else "center", **text)
        v = scene.inputs.vehicles[i]
        start = footprint_box(float(v.length), float(v.width), float(v.cg_to_front), starts[0], math.radians(yaws[0]))
        draw_footprint(ax, start, color, "-", alpha=0.3, lw=0.7, gid=f"approach-outline-{i}")
        if label is not None:  # one legend entry, in a neutral colour: every vehicle's approach is drawn alike
            ax.plot([], [], "--", color="0.3", lw=0.9, marker="o", ms=4, mfc="white", mec="0.3", label=label)
            label = None


def hitch_point(position, yaw, point_on_tow):
    """(2,) m: a tow's hitch point, its CG ``position`` (2,) plus ``point_on_tow`` (2,), its body frame point, turned
    by its ``yaw`` (rad): where the joint holds the towed vehicle's hitch point."""
    c, s = math.cos(yaw), math.sin(yaw)
    p = np.asarray(point_on_tow, float)
    return np.asarray(position, float)[:2] + np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])


def draw_hitches(ax, solution, scene):
    """Each hitch (``case.motion.links``, its points ``case.inputs.hitches``) at the first exchange (where the
    outlines are, ``scene``) and at rest (the rest results, where the case has a road): a diamond at the tow's hitch
    point (filled in the towed vehicle's colour) and a thin dark line from the tow's CG through it to the towed
    vehicle's CG, so that the line's bend shows the articulation. One legend entry for all of them."""
    case, rest = solution.case, solution.result.rest
    if case.motion is None:  # a hitch needs a road: none without one
        return
    label = "hitch: the tow's hitch point (diamond), joined to the two CGs"
    for (towed, tow, _), hitch in zip(case.motion.links, case.inputs.hitches):
        poses = [("", scene.cgs[tow], scene.yaws[tow], scene.cgs[towed])]
        if rest is not None and rest[tow] is not None and rest[towed] is not None:
            poses.append(("rest-", rest[tow].rest_position, math.radians(float(rest[tow].rest_yaw)),
                          rest[towed].rest_position))
        for prefix, cg, yaw, towed_cg in poses:
            cg, towed_cg = np.asarray(cg, float)[:2], np.asarray(towed_cg, float)[:2]
            point = hitch_point(cg, yaw, hitch.point_on_tow)
            ax.plot(*np.stack([cg, point, towed_cg]).T, "-", color="0.15", lw=0.9, zorder=5.5,
                    gid=f"{prefix}hitch-line-{towed}")
            ax.plot(*point, "D", ms=6, mfc=vehicle_color(towed), mec="0.15", mew=1.0, zorder=6,
                    gid=f"{prefix}hitch-{towed}", label=label)
            label = None  # one legend entry for every hitch


def draw_measured_rest(ax, names, evidence, sigma):
    """An x at each vehicle's measured rest position where ``evidence`` gives both its coordinates, and with
    ``sigma`` (both coordinates' standard errors given) an ellipse of those semi-axes about it: the region
    within one standard error in each coordinate, which the drawn rest CG is to be compared with."""
    from matplotlib.patches import Ellipse

    if not evidence:
        return
    given = {canonical_path(k): float(v) for k, v in evidence.items()}
    spread = {canonical_path(k): float(v) for k, v in (sigma or {}).items()}
    for i in range(len(names)):  # a fixed object (after the vehicles) has no rest position: none is given
        keys = [f"vehicles[{i}].rest_position[{k}]" for k in (0, 1)]
        if not all(k in given for k in keys):
            continue
        x, y = (given[k] for k in keys)
        s = [spread.get(k) for k in keys]
        within = f", +/- ({s[0]:.2f}, {s[1]:.2f}) m dashed" if None not in s else ""
        ax.plot(x, y, "x", color=vehicle_color(i), ms=10, mew=2.2, zorder=6, gid=f"measured-rest-{i}",
                label=f"{names[i]} measured rest: ({x:.2f}, {y:.2f}) m, ({x / U.FT:.1f}, {y / U.FT:.1f}) ft{within}")
        if None not in s:
            ax.add_patch(Ellipse((x, y), 2 * s[0], 2 * s[1], fill=False, edgecolor=vehicle_color(i), ls="--", lw=1.0,
                                 zorder=6, gid=f"measured-rest-sigma-{i}"))
