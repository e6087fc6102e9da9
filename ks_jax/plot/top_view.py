"""The top view of a solved contact: footprints, overlap, centroid, plane, normal, impulse, friction cone,
and, for a case with a road, each vehicle's motion from the exchange to rest.

matplotlib is imported only inside the functions (it is the ``plot`` extra). The contact is drawn in NumPy
from a ``ks_jax.solve.Solution`` (its case inputs and its results): the footprints move freely from the case
state (docs/model.md, "Automatic contact", as ``ks_jax.model.contact`` moves them), so a case without a
road needs no JAX call. The motion to rest and the approach are drawn step by step: ``solve`` keeps every step of
a case with a road, and ``ks_jax.solve.cases.trajectories`` reads those paths (or, for a case solved without them,
solves it once more keeping them). The contact and the exchanges are drawn here; each vehicle's way (its approach,
path to rest, hitches and measured rest) by ``plot.trajectory``, every footprint by ``plot.outline``.

A case has 1 to 8 vehicles and 0 to 8 fixed objects (its bodies: ``case.inputs.vehicles``, the vehicles and then
the objects); its first exchange is between two of them, ``case.between`` (its vehicle 1, and its vehicle 2, a
vehicle or a fixed object). Each vehicle has its own colour (``outline.COLORS``, by its index) and its name in the
legend.
What the top view draws (global frame, metres; a second axis in feet):
- every vehicle's outline at first contact t_i (dashed; automatic contact only) and at the first exchange (solid),
  the front face thicker; every fixed object as what it is (a wall as its hatched face, a pole as its circle, a
  barrier as its box; grey), with its name; the overlap polygon of the first exchange's pair at the exchange (grey);
- the first exchange's impulse centroid P, the contact plane (red line through P, perpendicular to n), the normal
  n (red arrow, from its vehicle 2 into its vehicle 1), the friction cone (cyan wedge about n, half-angle atan(mu));
- the impulse on each vehicle of that pair (J on vehicle 1, -J on vehicle 2, drawn at P: its horizontal part; a
  fixed object gets none), and each vehicle's CG velocity before (dotted) and after (solid) the first exchange
  (a vehicle that took no part in it keeps its velocity);
- whether the contact slides (the impulse on the cone's edge, |T| = mu N: that edge drawn dashed
  beyond the wedge) or sticks (inside the cone), in the title and the legend;
- where the case has a road (``solution.result.rest`` is not None), each vehicle's motion from the exchange to
  rest: its CG's path (a thin line), its outline at ``trajectory.PATH_OUTLINES`` instants evenly spaced in time
  along the way (thin, faded: they bunch up where it slows down), and its outline at rest (solid, lightly filled, with a
  dot at its CG; "at rest" in the legend, or "at the time limit" for one that had not stopped by then);
- where a vehicle has an approach (docs/model.md, "The approach"; ``solution.result.approach``), its CG's path from
  the approach's start to the impact (dashed, thin: the same trajectory as its path to rest, before the impact; with
  automatic contact carried on, moving freely, to its CG at the first exchange), a small open circle at the start of
  each phase with its time from the impact ("-1.23 s"), and its outline at the approach's start (thin, faded);
- where the case had more than one exchange (docs/model.md, "Contact interactions"; ``Solution.exchange_list``),
  every later one where it happened, whichever pair of bodies exchanged it, numbered as the panel numbers them
  (#0 is the first, drawn as above): one whose impulse is at least ``LATER_SHARE`` of the largest exchange's gets
  an open circle at its centroid, its number, its normal (a short red arrow) and its impulse on each vehicle of its
  pair (on the first's scale: one scale for every exchange's arrows), the smaller ones only a dot (a push of many
  small exchanges stays readable); the legend says how many exchanges there were, and how many of each kind are
  drawn;
- where a vehicle is towed (docs/model.md, "Articulated vehicles"), each hitch at the first exchange and, for a
  case with a road, at rest: a diamond at the tow's hitch point (its CG plus ``point_on_tow`` turned by its yaw)
  and a thin line from the tow's CG to it and on to the towed vehicle's CG, whose bend is the articulation;
- where a vehicle has a measured crush profile (docs/model.md, "Crush energy"; ``case.crush``), that profile to
  scale on its damaged side at the first exchange (``crush_profile.draw_profiles``);
- given ``evidence`` (result path -> measured value, SI), each vehicle's measured rest position where both
  of its coordinates are given (rest_position[0] and [1]): an x, "measured rest" in the legend, and with
  ``sigma`` (path -> SI) an ellipse of semi-axes sigma_x, sigma_y about it (a circle for equal sigmas).
The legend states each arrow's scale as "1 m = X": an arrow's drawn length in metres is its
quantity divided by X, X a round number (``round_scale``).
The axes take in everything drawn: the whole paths (the approaches' too), the rest outlines, the fixed objects and
the measured positions included.
Artists a program may look for carry a gid (i a body's index, 0-based, as in ``case.inputs.vehicles``; k a fixed
object's, as in ``case.fixed``): "outline-i" (vehicle i's closed outline at the first exchange),
"first-contact-outline-i" (at first contact), "fixed-k" (fixed object k's patch), "impulse-i" (the first exchange's
impulse arrow on vehicle i), "rest-path-i" (the CG path of vehicle i), "path-outline-i" (its outlines on the way),
"rest-outline-i" (its closed outline at rest), "rest-cg-i", "measured-rest-i" and "measured-rest-sigma-i";
"hitch-i" and "hitch-line-i" (the marker and the line of the hitch that tows vehicle i, at the first exchange),
"rest-hitch-i" and "rest-hitch-line-i" (at rest); "approach-path-i" (the CG path of vehicle i's approach),
"approach-phase-i-k" (the marker at the start of its phase k, 0-based, earliest first), "approach-time-i-k" (that
phase's start time, the text beside it) and "approach-outline-i" (its closed outline at the approach's start); and,
for a case with more than one exchange, "exchange-k" (the marker at the centroid of exchange k >= 1),
"exchange-number-k" (the text "#k", k = 0 included), "exchange-normal-k" and "exchange-impulse-k-i" (the impulse arrow
of exchange k on vehicle i); "crush-profile-i" (vehicle i's crushed outline).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .. import units as U
from ..case import CaseInputs, impulse_exchanged, visible, visible_lines
from ..model.types import ExchangeResult
from ..solve.cases import trajectories
from .crush_profile import draw_profiles
from .outline import clip_polygon, draw_footprint, footprint_box, vehicle_color
from .trajectory import draw_approaches, draw_hitches, draw_measured_rest, draw_motion_to_rest
from .text import wrap_to_width

# one colour per vehicle, by its index (a case has at most 8): tab10 without the red, cyan and grey that draw the
# contact (plane, normal, cone) and the fixed objects, and magenta for the eighth (not the navy of a sliding contact's
# cone edge, nor the black of the centroids)
IMPULSE_LENGTH = 0.4  # the longest impulse arrow, in units of the larger vehicle's length or width
VELOCITY_LENGTH = 0.5  # the longest velocity arrow, likewise
ROUND_STEPS = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0)  # of a scale, times a power of ten
LEGEND_SIZE = 6.5  # points, the legend's font
TITLE_SIZE = 9.0  # points, the title's font
TWO_COLUMNS = 420.0  # points: an axes at least this wide has its legend in two columns
PANEL_WIDTH = 8.5  # inches, one panel of ``save_top_view``
PLOT_HEIGHT = 7.2  # inches of a panel above its legend: the axes, its labels and a two-line title
LATER_SHARE = 0.05  # a later exchange is numbered and drawn whole where its impulse is this share of the largest
LATER_NORMAL = 0.25  # a later exchange's normal arrow, in units of the larger vehicle's length or width


def round_scale(x):
    """The least of ``ROUND_STEPS`` times a power of ten that is at least ``x`` > 0: an arrow's scale
    that reads exactly ("1 m = 2,500 N s"), and keeps the longest arrow between 2/3 of and its
    intended length."""
    power = 10.0 ** math.floor(math.log10(x))
    return next((step * power for step in ROUND_STEPS if step * power >= x * (1 - 1e-12)), 10.0 * power)


def scale_text(x):
    """A scale from ``round_scale`` as written in the legend, with every digit it has."""
    return f"{x:,.0f}" if x >= 10 else f"{x:.6g}"


def _legend(ax, offset):
    """The legend below the axes, ``offset`` points under its bottom (below the x label), centred on it,
    in two columns on an axes at least ``TWO_COLUMNS`` points wide (one on a narrower one), each entry
    wrapped to its column's width: however long the vehicles' names, the legend is no wider than the axes."""
    from matplotlib.transforms import offset_copy

    handles, labels = ax.get_legend_handles_labels()
    fig = ax.figure
    width = ax.get_position().width * fig.get_figwidth() * 72.0  # points
    ncol = 2 if width >= TWO_COLUMNS else 1
    # matplotlib's legend: a handle 2.0 and a gap 0.8 font sizes per entry, 2.0 between columns, 0.4 each side
    column = (width - LEGEND_SIZE * (0.8 + 2.8 * ncol + 2.0 * (ncol - 1))) / ncol
    labels = [wrap_to_width(label, 0.97 * column, LEGEND_SIZE) for label in labels]
    below = offset_copy(ax.transAxes, fig=fig, y=-offset, units="points")
    return ax.legend(handles, labels, fontsize=LEGEND_SIZE, loc="upper center", bbox_to_anchor=(0.5, 0.0),
                     bbox_transform=below, ncol=ncol, frameon=False)


def _vehicle_boxes(inputs, t):
    """Footprint corners of every body after free motion for ``t`` s (a fixed object, at rest, stays where it is),
    their CGs (2,) and their yaws (rad)."""
    boxes, cgs, yaws = [], [], []
    for v in inputs.vehicles:
        vel = float(v.speed) * np.array([math.cos(float(v.course)), math.sin(float(v.course))])
        xy = np.asarray(v.position, float)[:2] + vel * t
        yaw = float(v.yaw) + float(np.asarray(v.angular_velocity)[2]) * t
        boxes.append(footprint_box(float(v.length), float(v.width), float(v.cg_to_front), xy, yaw))
        cgs.append(xy)
        yaws.append(yaw)
    return boxes, cgs, yaws


def _arrow(ax, tip, tail, props, **kw):
    """An arrow from ``tail`` to ``tip`` (data coordinates) that the axes' limits take in: matplotlib
    leaves an annotation out of the autoscaling, and does not draw it at all where its tip is outside.
    Returns the annotation."""
    arrow = ax.annotate("", tip, tail, arrowprops=props, **kw)
    ax.update_datalim(np.array([tip, tail], float))
    return arrow


def _friction_state(ax, c, p, n, mu, j, reach):
    """Say whether the contact slides or sticks. Sliding: the impulse lies on the cone's edge (|T| = mu N),
    and the edge on the side of its horizontal tangential part is drawn dashed out to ``reach`` and a
    little past it (past the arrow's head where the arrow is longer than the wedge), so that the arrow
    is seen to lie along it. Sticking: the impulse is inside the cone, |T| / N <= mu."""
    if bool(c.sliding):
        t = np.array([-n[1], n[0]])
        side = 1.0 if float(np.dot(j, t)) >= 0 else -1.0
        edge = (n + side * mu * t) / math.hypot(1.0, mu)
        ax.plot(*np.stack([p, p + 1.15 * reach * edge]).T, "--", color="navy", lw=1.2, zorder=3.5,
                label="sliding: |T| = mu N, impulse on the cone's edge (dashed)")
    else:
        normal, tangential = float(c.impulse_normal), float(c.impulse_tangential)
        ratio = f"{tangential / normal:.3f}" if normal > 0 else "undefined"
        ax.plot([], [], " ", label=f"sticking (inside the cone): |T| / N = {ratio} <= mu = {mu:g}")


class _Scene(NamedTuple):
    """What the parts of one top view share: the case, the vehicles drawn, the first exchange's pair, and where
    every body is at the first exchange (``_draw_outlines`` makes it)."""

    inputs: CaseInputs  # the case's inputs
    result: ExchangeResult  # its results (NumPy arrays; ``vehicles`` one per body, in body order)
    names: list  # every body's name (the vehicles', then the fixed objects'), control characters as their escapes
    count: int  # how many bodies are vehicles (the first ``count`` of ``inputs.vehicles``), drawn moving; the fixed
    # objects after them are drawn once, as what they are
    between: tuple  # the first exchange's bodies: its vehicle 1, and its vehicle 2 (a vehicle or a fixed object)
    many: bool  # more than two bodies: the legend names the first exchange's pair where two bodies need no names
    no_contact: bool  # no contact within the search horizon
    extent: float  # the largest vehicle's length or width, m: the scale of the arrows and the contact
    boxes: list  # each body's footprint corners at the first exchange (4, 2)
    cgs: list  # each body's CG at the first exchange (2,)
    yaws: list  # each body's yaw at the first exchange, rad


def _title(ax, solution, solved):
    """The case's name and its status (and, where an impulse was exchanged, whether the contact slides or
    sticks), wrapped to the axes' width."""
    case, res = solution.case, solution.result
    friction = ""
    if solved and solution.status != "no_contact" and bool(impulse_exchanged(res)):
        friction = ", sliding (|T| = mu N)" if bool(res.contact.sliding) else ", sticking (inside the cone)"
    width = ax.get_position().width * ax.figure.get_figwidth() * 72.0  # points
    title = f"{visible_lines(case.name)}\nstatus: {solution.status}{friction}"
    ax.set_title(wrap_to_width(title, width, TITLE_SIZE, indent=""), fontsize=TITLE_SIZE)


def _draw_outlines(ax, solution, names, exchanges):
    """Every vehicle's footprint at first contact t_i (dashed; automatic contact only) and at the first exchange
    (solid), those not in its pair moved freely for as long as the pair (as the pipeline moves them), and every fixed
    object (``_draw_fixed``: a wall's face long enough to take in every exchange with it, of ``exchanges``); returns
    the ``_Scene`` the other parts draw from."""
    case, res = solution.case, solution.result
    inputs = case.inputs
    auto = case.auto_point or case.auto_normal
    t_i = float(res.contact.time)
    no_contact = solution.status == "no_contact"
    t_x = 0.0 if (no_contact or not auto) else t_i + float(inputs.contact.penetration_time)
    count = case.vehicle_count  # the fixed objects after the vehicles are drawn as what they are, once
    many = len(inputs.vehicles) > 2
    if auto and not no_contact:
        first, _, _ = _vehicle_boxes(inputs, t_i)
        for i in range(count):
            draw_footprint(ax, first[i], vehicle_color(i), "--", alpha=0.6, gid=f"first-contact-outline-{i}",
                           label=f"{names[i]} at first contact, t_i = {t_i:.4f} s")
    boxes, cgs, yaws = _vehicle_boxes(inputs, t_x)
    exchange = "the first exchange" if many else "the exchange"
    when = ("at the case state (no contact)" if no_contact else f"at {exchange}, t = {t_x:.4f} s" if auto
            else "at the case state (explicit contact)")
    for i in range(count):
        draw_footprint(ax, boxes[i], vehicle_color(i), "-", label=f"{names[i]} {when}", gid=f"outline-{i}")
    extent = max(max(float(v.length), float(v.width)) for v in inputs.vehicles[:count])
    for k, obj in enumerate(case.fixed):
        b = count + k
        # the centroids of the exchanges with it, in time order: the face is drawn about the first of them
        mine = [ex["point"] for ex in exchanges if case.body_path(b) in ex["between"]]
        mine = [np.asarray(q, float)[:2] for q in mine if q is not None]
        mine = [q for q in mine if np.all(np.isfinite(q))]
        near = mine[0] if mine else _unstruck_near(obj, cgs[:count])
        _draw_fixed(ax, obj, names[b], boxes[b], near, extent, mine[1:], gid=f"fixed-{k}")
    return _Scene(inputs, res, names, count, tuple(case.between), many, no_contact, extent, boxes, cgs, yaws)


def _unstruck_near(obj, cgs):
    """Where a fixed object that no exchange touched is drawn about (``_draw_fixed``'s ``near``): a wall's face about
    the foot of the vehicle CG nearest it (of ``cgs``), a pole or a barrier about its position."""
    if obj.kind != "wall":
        return np.asarray(obj.position, float)[:2]
    n = np.array([math.cos(obj.normal), math.sin(obj.normal)])
    return min(cgs, key=lambda cg: abs(float(n @ (cg - np.asarray(obj.point, float)[:2]))))


def _draw_overlap(ax, scene, fixed):
    """The overlap of the first exchange's pair at the exchange (grey): its vehicle 1's footprint with its vehicle
    2's, or with the fixed object ``fixed`` it strikes (``case.struck_object``: a pole's disc, not the square about
    it)."""
    from matplotlib.patches import Polygon

    one, two = scene.between
    other = scene.boxes[two]
    if fixed is not None and fixed.kind == "pole":  # the disc, not the square about it
        angle = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
        other = fixed.position + 0.5 * fixed.diameter * np.stack([np.cos(angle), np.sin(angle)], -1)
    overlap = clip_polygon(scene.boxes[one], other)
    label = (f"overlap of {scene.names[one]} and {scene.names[two]} at the first exchange" if scene.many
             else "overlap of the footprints")
    if len(overlap) >= 3:
        ax.add_patch(Polygon(overlap, closed=True, facecolor="0.6", edgecolor="0.3", alpha=0.5, label=label))


def _draw_plane_and_cone(ax, scene, p, n, mu):
    """The contact plane (red line through the centroid ``p``, perpendicular to ``n``), the normal (red
    arrow) and the friction cone of half-angle atan(``mu``) about it (cyan). Returns the cone's radius, m."""
    from matplotlib.patches import Wedge

    tang = np.array([-n[1], n[0]])
    half = 0.45 * scene.extent
    ax.plot(*np.stack([p - half * tang, p + half * tang]).T, "-", color="red", lw=1.2, label="contact plane")
    # thin and on top: an impulse arrow along n (an inline impact) shows on both sides of it
    _arrow(ax, p + 0.4 * scene.extent * n, p, dict(arrowstyle="-|>", color="red", lw=1.2), zorder=5)
    one, two = (scene.names[b] for b in scene.between)
    into = f"from {two} into {one}" if scene.many else "from 2 into 1"
    ax.plot([], [], color="red", marker=r"$\rightarrow$", ls="", ms=12, label=f"normal n ({into})")
    half_angle = math.degrees(math.atan(mu))
    az = math.degrees(math.atan2(n[1], n[0]))
    cone = 0.3 * scene.extent
    ax.add_patch(Wedge(p, cone, az - half_angle, az + half_angle, facecolor="tab:cyan", alpha=0.25,
                       edgecolor="darkcyan", label=f"friction cone, mu = {mu:g} (half-angle {half_angle:.1f} deg)"))
    return cone


def horizontal_part(impulse):
    """The length of an impulse's horizontal part (what its arrow draws), N s: 0 for an impulse that is
    undefined (None) or not finite."""
    if impulse is None:
        return 0.0
    size = float(np.linalg.norm(np.asarray(impulse, float)[:2]))
    return size if math.isfinite(size) else 0.0


def impulse_scale(exchanges, extent):
    """N s per m of impulse arrow, one scale for every exchange's arrows so that their sizes compare: the round
    scale (``round_scale``) that draws the largest horizontal impulse of ``exchanges`` (``Solution.exchange_list``;
    the first exchange's unless a later one is larger) at most ``IMPULSE_LENGTH`` times ``extent`` long. None where
    no exchange has a horizontal impulse."""
    largest = max((horizontal_part(ex["impulse"]) for ex in exchanges), default=0.0)
    return round_scale(largest / (IMPULSE_LENGTH * extent)) if largest > 0 else None


def _impulse_scale_entry(ax, per_m):
    """The legend's entry for the impulse arrows' scale ``per_m`` (N s per m)."""
    ax.plot([], [], " ", label=f"impulse arrows: 1 m = {scale_text(per_m)} N s "
                               f"({per_m / U.LBF_S:,.6g} lbf s)")


def _draw_impulse(ax, scene, p, j, per_m):
    """The impulse's horizontal part ``j`` on each vehicle of the first exchange's pair at the centroid ``p`` (J on
    its vehicle 1, -J on its vehicle 2; none on a fixed object), each in its vehicle's colour, on the scale
    ``per_m`` (N s per m, ``impulse_scale``) the legend states. Returns the arrows' length, m (0 for no impulse)."""
    c = scene.result.contact
    j_mag = float(np.linalg.norm(j))  # the arrow: the horizontal part
    total = float(c.impulse_magnitude)
    if j_mag <= 0:
        return 0.0
    shown = f"{j_mag:,.0f}"  # where the impulse has a vertical part, the arrow is shorter than it
    vertical = "" if shown == f"{total:,.0f}" else f", horizontal part {shown} N s"
    for b, sign in zip(scene.between, (1.0, -1.0)):
        if b >= scene.count:  # a fixed object: no arrow
            continue
        _arrow(ax, p + sign * j / per_m, p, dict(arrowstyle="-|>", color=vehicle_color(b), lw=3.5), zorder=4,
               gid=f"impulse-{b}")
        ax.plot([], [], color=vehicle_color(b), lw=3.5,
                label=f"impulse on {scene.names[b]}: {total:,.0f} N s ({total / U.LBF_S:,.0f} lbf s){vertical}")
    _impulse_scale_entry(ax, per_m)
    return j_mag / per_m


def _draw_contact(ax, scene, fixed, per_m):
    """The first exchange's contact (between its pair, ``scene.between``; ``fixed``: the fixed object it strikes,
    or None): the overlap, the plane, the normal, the friction cone, the impulse on each vehicle of the pair
    (``per_m`` N s per m of arrow), whether it slides or sticks, and the impulse centroid P (a black x)."""
    c = scene.result.contact
    _draw_overlap(ax, scene, fixed)
    p = np.asarray(c.point, float)[:2]
    n3 = np.asarray(c.normal, float)
    n = n3[:2] / max(np.linalg.norm(n3[:2]), 1e-12)
    mu = float(scene.inputs.contact.friction)
    cone = _draw_plane_and_cone(ax, scene, p, n, mu)
    j = np.asarray(c.impulse, float)[:2]
    arrow = _draw_impulse(ax, scene, p, j, per_m)
    if bool(impulse_exchanged(scene.result)):
        _friction_state(ax, c, p, n, mu, j, max(cone, arrow))
    ax.plot(*p, "kx", ms=9, mew=2, label=f"impulse centroid ({p[0]:.3f}, {p[1]:.3f}) m")


def _draw_later_exchanges(ax, scene, exchanges, per_m):
    """Every exchange after the first (``exchanges``: ``Solution.exchange_list``, two or more) where it happened,
    whichever pair of bodies exchanged it, the outlines staying at the first exchange. One whose impulse is at least
    ``LATER_SHARE`` of the largest exchange's: an open circle at its centroid, its number "#k" as the panel's (and
    "#0" beside the first's), its normal (a short red arrow, from the pair's second body into its first) and its
    horizontal impulse on each vehicle of the pair (J on the first, -J on the second, each in its vehicle's colour;
    none on a fixed object) on the first's scale ``per_m``, so that their sizes compare (``impulse_scale``: one
    scale for every exchange's arrows). A smaller one: a dot at its centroid only, so that a push of many small
    exchanges does not hide the picture. The legend says how many exchanges there were and how many of each kind are
    drawn."""
    sizes = [float(ex["impulse_magnitude"] or 0.0) for ex in exchanges]
    sizes = [size if math.isfinite(size) else 0.0 for size in sizes]
    largest = max(sizes)
    share = f"{LATER_SHARE:.0%}"
    later = [(ex, size > 0 and size >= LATER_SHARE * largest) for ex, size in zip(exchanges[1:], sizes[1:])
             if ex["point"] is not None and all(map(math.isfinite, ex["point"][:2]))]
    count = len(exchanges)
    numbers = "#1" if count == 2 else f"#1 to #{count - 1}"
    ax.plot([], [], " ", label=f"{count} exchanges, numbered as the panel numbers them: #0 the first (drawn as "
                               f"above), {numbers} later, each where it happened")
    number = dict(textcoords="offset points", xytext=(5, 5), fontsize=7, zorder=7,
                  bbox=dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="none", alpha=0.7))
    if not scene.no_contact:
        ax.annotate("#0", np.asarray(scene.result.contact.point, float)[:2], gid="exchange-number-0", **number)
    drawn = [sum(1 for _, big in later if big), sum(1 for _, big in later if not big)]
    labels = [f"later exchange ({drawn[0]}, impulse at least {share} of the largest, {largest:,.0f} N s): its "
              "centroid (o), number, normal (red) and impulse (on the same scale)",
              f"smaller later exchange ({drawn[1]}, impulse under {share} of the largest): its centroid (dot)"]
    arrows = False
    for ex, big in later:
        k, p = ex["index"], np.asarray(ex["point"], float)[:2]
        style = (dict(marker="o", ms=6, mfc="none", mec="black", mew=1.2) if big
                 else dict(marker="o", ms=2, color="0.2", alpha=0.7))
        ax.plot(*p, ls="", zorder=6, gid=f"exchange-{k}", label=labels[0 if big else 1], **style)
        labels[0 if big else 1] = None  # one legend entry for each kind
        if not big:
            continue
        ax.annotate(f"#{k}", p, gid=f"exchange-number-{k}", **number)
        n = np.asarray(ex["normal"] if ex["normal"] is not None else [math.nan] * 3, float)[:2]
        if np.all(np.isfinite(n)) and np.linalg.norm(n) > 1e-12:
            n = n / np.linalg.norm(n)
            _arrow(ax, p + LATER_NORMAL * scene.extent * n, p, dict(arrowstyle="-|>", color="red", lw=1.0), zorder=5,
                   gid=f"exchange-normal-{k}")
        if per_m is None or horizontal_part(ex["impulse"]) <= 0:
            continue
        j = np.asarray(ex["impulse"], float)[:2]
        for side, body in enumerate(ex["between"]):
            if isinstance(body, int) and body < scene.count:  # a vehicle (a fixed object is "fixed[k]")
                sign = 1.0 if side == 0 else -1.0
                _arrow(ax, p + sign * j / per_m, p, dict(arrowstyle="-|>", color=vehicle_color(body), lw=2.0),
                       zorder=4, gid=f"exchange-impulse-{k}-{body}")
                arrows = True
    if arrows and horizontal_part(exchanges[0]["impulse"]) <= 0:  # the first drew no arrow, nor the scale
        _impulse_scale_entry(ax, per_m)


def _draw_velocities(ax, scene):
    """Each vehicle's CG velocity before (dotted) and after (solid) the first exchange, from its CG at the
    exchange, on one round scale (``round_scale``) the legend states (a vehicle not in the exchange keeps its
    velocity: its two arrows are alike)."""
    vehicles = scene.inputs.vehicles[:scene.count]
    speeds = []
    for i, v in enumerate(vehicles):
        speeds.append(float(v.speed))
        speeds.append(float(np.linalg.norm(np.asarray(scene.result.vehicles[i].velocity_after, float)[:2])))
    vmax = max(speeds)
    if vmax <= 0:
        return
    v_per_m = round_scale(vmax / (VELOCITY_LENGTH * scene.extent))  # m/s per m of arrow
    v_scale = 1.0 / v_per_m  # m per m/s
    for i, v in enumerate(vehicles):
        before = float(v.speed) * np.array([math.cos(float(v.course)), math.sin(float(v.course))])
        after = np.asarray(scene.result.vehicles[i].velocity_after, float)[:2]
        cg = scene.cgs[i]
        for vec, style, side in ((before, ":", 1.0), (after, "-", -1.0)):
            length = float(np.linalg.norm(vec))
            if length == 0:
                continue
            # before on the left of the arrow's line, after on its right, so that they never hide
            # each other or the impulse arrows of an inline impact
            shift = side * 0.05 * scene.extent * np.array([-vec[1], vec[0]]) / length
            _arrow(ax, cg + shift + v_scale * vec, cg + shift,
                   dict(arrowstyle="-|>", color=vehicle_color(i), lw=1.3, ls=style))
        ax.plot(*cg, "o", color=vehicle_color(i), ms=4)
    unit = f"1 m = {scale_text(v_per_m)} m/s = {v_per_m / U.MPH:.2f} mph"
    ax.plot([], [], color="0.3", ls=":", label=f"CG velocity before ({unit})")
    ax.plot([], [], color="0.3", ls="-", label=f"CG velocity after ({unit})")


def _finish_axes(ax):
    """Limits that take in everything drawn (the arrows' ends too), equal scales, the axes in metres with a
    second pair in feet, a grid, and the legend below."""
    ax.autoscale_view()  # with the arrows' ends in the data limits
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, lw=0.3)
    sec = ax.secondary_xaxis("top", functions=(lambda m: m / U.FT, lambda f: f * U.FT))
    sec.set_xlabel("x (ft)", fontsize=8)
    sec = ax.secondary_yaxis("right", functions=(lambda m: m / U.FT, lambda f: f * U.FT))
    sec.set_ylabel("y (ft)", fontsize=8)
    # below the x label whatever the axes' height: a fixed offset in points, not in axes fractions
    _legend(ax, 34)


def top_view(solution, ax=None, evidence=None, sigma=None):
    """Draw one solved case (a ``Solution`` from ``ks_jax.solve``) on ``ax`` (a new figure if None).
    ``evidence``: None, or a mapping of result path -> measured value (SI) whose rest positions
    ("vehicles[i].rest_position[0]" and "[1]") are marked; ``sigma``: None, or path -> standard error (SI)
    of those, drawn about the marks. Other paths are ignored. Returns the axes."""
    import matplotlib.pyplot as plt

    if not (hasattr(solution, "case") and hasattr(solution, "result")):
        raise TypeError(f"top_view: a Solution from ks_jax.solve is drawn, not a {type(solution).__name__} (solve a "
                        "Case first: ks_jax.solve(case))")
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 7))
    case = solution.case
    names = [visible(n) for n in case.vehicle_names]  # a name's control characters drawn as their escapes
    solved = not (case.inputs is None or solution.result is None or solution.status.startswith("invalid"))
    _title(ax, solution, solved)
    if not solved:
        ax.text(0.5, 0.5, f"not solved: {solution.status}", ha="center", va="center", transform=ax.transAxes)
        return ax
    exchanges = solution.exchange_list()  # the first, and those of the watched motion (a case with a road)
    scene = _draw_outlines(ax, solution, names, exchanges)
    per_m = impulse_scale(exchanges, scene.extent)
    if not scene.no_contact:
        _draw_contact(ax, scene, case.struck_object, per_m)
    if len(exchanges) > 1:
        _draw_later_exchanges(ax, scene, exchanges, per_m)
    _draw_velocities(ax, scene)
    if scene.no_contact:
        ax.text(0.02, 0.02, "no contact within the search horizon", transform=ax.transAxes, fontsize=8)
    paths = None
    if solution.result.rest is not None or solution.result.approach is not None:
        paths = trajectories(solution)  # every step of the motions: None without a road
    if solution.result.rest is not None and paths is not None:
        draw_motion_to_rest(ax, solution, scene.count, paths.rest)
    if solution.result.approach is not None and paths is not None and paths.approach is not None:
        draw_approaches(ax, solution, scene, paths.approach)
    draw_hitches(ax, solution, scene)
    draw_profiles(ax, case, exchanges, scene.cgs, scene.yaws, [vehicle_color(i) for i in range(scene.count)], names)
    draw_measured_rest(ax, names, evidence, sigma)
    _finish_axes(ax)
    return ax


def _draw_fixed(ax, obj, name, box, near, extent, later=(), gid=None):
    """A fixed object (``case.fixed.FixedObject``) named ``name``, its patch carrying ``gid``: a wall as its face,
    hatched on the wall's side, for 1.2 vehicle lengths each way of ``near`` (the centroid of its first exchange,
    or for a wall no exchange touched the CG of the vehicle nearest it: the face about that point's foot) and of each
    of ``later`` (the centroids of later exchanges with it, so that none is drawn off the face's end); a pole as its
    circle; a barrier as its box (``box``, its corners); grey, filled."""
    from matplotlib.patches import Circle, Polygon

    style = dict(facecolor="0.75", edgecolor="0.25", hatch="///", lw=1.4, alpha=0.9, zorder=1)
    if obj.kind == "wall":
        n = np.array([math.cos(obj.normal), math.sin(obj.normal)])
        along = np.array([-n[1], n[0]])
        foot = obj.point + along * float(along @ (near - obj.point))  # the face's point nearest the centroid
        half, depth = 1.2 * extent, 0.15 * extent
        reach = [float(along @ (np.asarray(q, float) - foot)) for q in later]  # each later centroid along the face
        reach = [r for r in reach if math.isfinite(r)]
        face = [foot + (min([0.0, *reach]) - half) * along, foot + (max([0.0, *reach]) + half) * along]
        ax.add_patch(Polygon([*face, face[1] - depth * n, face[0] - depth * n], closed=True,
                             label=f"{name} (fixed wall; its face)", gid=gid, **style))
        ax.plot(*np.stack(face).T, "-", color="0.1", lw=2.5)
    elif obj.kind == "pole":
        ax.add_patch(Circle(obj.position, 0.5 * obj.diameter, label=f"{name} (fixed pole, {obj.diameter:.3f} m)",
                            gid=gid, **style))
    else:
        ax.add_patch(Polygon(box, closed=True, label=f"{name} (fixed barrier)", gid=gid, **style))
    ax.update_datalim(np.asarray(box if obj.kind == "barrier" else [near - extent, near + extent], float))


def top_view_figure(solutions, evidence=None, sigma=None):
    """A figure of the top views of one ``Solution`` or a list of them (one panel each, two per row), every
    title and legend inside it: each panel is ``PANEL_WIDTH`` inches wide, and each row as tall as its
    plots (``PLOT_HEIGHT``) and its tallest legend and title need, however long the case's and the
    vehicles' names (``top_view`` wraps them to the axes' width). ``evidence`` and ``sigma`` as for
    ``top_view``: one mapping for every panel, or a list of them (or None), one per solution."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure  # no pyplot: works without a display, leaves no state

    if not isinstance(solutions, (list, tuple)):
        solutions = [solutions]
    n = len(solutions)
    if n == 0:
        raise ValueError("save_top_view: no solution given: pass a Solution from ks_jax.solve, or a list of them")
    evidence = list(evidence) if isinstance(evidence, (list, tuple)) else [evidence] * n
    sigma = list(sigma) if isinstance(sigma, (list, tuple)) else [sigma] * n
    if len(evidence) != n or len(sigma) != n:
        raise ValueError(f"save_top_view: {n} solution(s), {len(evidence)} evidence and {len(sigma)} sigma "
                         "mappings: give one mapping for all, or one per solution")
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(PANEL_WIDTH * cols, 9.0 * rows))
    FigureCanvasAgg(fig)  # a renderer, to measure the legends
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, sol, marks, sigmas in zip(axes.flat, solutions, evidence, sigma):
        top_view(sol, ax, evidence=marks, sigma=sigmas)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    renderer = fig.canvas.get_renderer()

    def extra(ax):  # inches a panel needs beyond PLOT_HEIGHT: its legend, and its title's lines past two
        legend = ax.get_legend()
        below = legend.get_window_extent(renderer).height if legend is not None else 0.0
        title = ax.title.get_window_extent(renderer).height
        return (below + max(0.0, title - 2.4 * TITLE_SIZE * fig.dpi / 72.0)) / fig.dpi

    heights = [PLOT_HEIGHT + max(extra(ax) for ax in row if ax.get_visible()) for row in axes]
    axes[0, 0].get_subplotspec().get_gridspec().set_height_ratios(heights)
    fig.set_figheight(sum(heights))
    fig.tight_layout()
    return fig


def save_top_view(solutions, path, evidence=None, sigma=None):
    """Write ``top_view_figure`` of one ``Solution`` or a list of them (one panel each) to ``path``
    (PNG, PDF, SVG: by the file name). ``evidence`` and ``sigma`` as for ``top_view``. Returns the path."""
    top_view_figure(solutions, evidence, sigma).savefig(path, dpi=110)
    return path
