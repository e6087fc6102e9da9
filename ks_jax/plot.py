"""Pictures: the top view of a solved contact (footprints, overlap, centroid, plane, normal, impulse,
friction cone) and the results of a sweep over its inputs (``sweep_view``, ``save_sweep_view``).

matplotlib is imported only inside the functions (it is the ``plot`` extra). Everything drawn is
computed here in NumPy from a ``ks_jax.solve.Solution`` (its case inputs and its results) or a
``ks_jax.sweeps.SweepResult``: the footprints move freely from the case state (MODEL.md section 5,
as ``ks_jax.geometry`` does), so no picture needs a JAX call.

What the top view draws (global frame, metres; a second axis in feet):
- outlines at first contact t_i (dashed; automatic contact only) and at the exchange (solid),
  the front face thicker; the overlap polygon at the exchange (grey);
- the impulse centroid P, the contact plane (red line through P, perpendicular to n), the normal
  n (red arrow, from vehicle 2 into vehicle 1), the friction cone (blue wedge about n,
  half-angle atan(mu));
- the impulse on each vehicle (J on vehicle 1, -J on vehicle 2, drawn at P), and each vehicle's
  CG velocity before (dotted) and after (solid). Arrow scales are given in the legend.
"""

from __future__ import annotations

import math

import numpy as np

from . import units as U

COLORS = ("tab:blue", "tab:orange")


def _box(length, width, cg_to_front, xy, yaw):
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


def _vehicle_boxes(inputs, t):
    """Footprint corners of both vehicles after free motion for ``t`` s, and their CGs (2,)."""
    boxes, cgs = [], []
    for v in inputs.vehicles:
        vel = float(v.speed) * np.array([math.cos(float(v.course)), math.sin(float(v.course))])
        xy = np.asarray(v.position, float)[:2] + vel * t
        yaw = float(v.yaw) + float(np.asarray(v.angular_velocity)[2]) * t
        boxes.append(_box(float(v.length), float(v.width), float(v.cg_to_front), xy, yaw))
        cgs.append(xy)
    return boxes, cgs


def _draw_box(ax, corners, color, style, label=None, alpha=1.0):
    closed = np.vstack([corners, corners[:1]])
    ax.plot(closed[:, 0], closed[:, 1], style, color=color, lw=1.4, label=label, alpha=alpha)
    ax.plot(corners[1:3, 0], corners[1:3, 1], style, color=color, lw=3.0, alpha=alpha)  # front face


def _arrow(ax, tip, tail, props, **kw):
    """An arrow from ``tail`` to ``tip`` (data coordinates) that the axes' limits take in: matplotlib
    leaves an annotation out of the autoscaling, and does not draw it at all where its tip is outside."""
    ax.annotate("", tip, tail, arrowprops=props, **kw)
    ax.update_datalim(np.array([tip, tail], float))


def top_view(solution, ax=None):
    """Draw one solved case (a ``Solution`` from ``ks_jax.solve``) on ``ax`` (a new figure if None).
    Returns the axes."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon, Wedge

    if ax is None:
        _, ax = plt.subplots(figsize=(8, 7))
    case, res = solution.case, solution.result
    names = case.vehicle_names
    ax.set_title(f"{case.name}\nstatus: {solution.status}", fontsize=9)
    if case.inputs is None or res is None or solution.status.startswith("invalid"):
        ax.text(0.5, 0.5, f"not solved: {solution.status}", ha="center", va="center", transform=ax.transAxes)
        return ax
    inputs = case.inputs
    auto = case.auto_point or case.auto_normal
    c = res.contact
    t_i = float(c.time)
    no_contact = solution.status == "no_contact"
    t_x = 0.0 if (no_contact or not auto) else t_i + float(inputs.contact.penetration_time)

    if auto and not no_contact:
        first, _ = _vehicle_boxes(inputs, t_i)
        for i in range(2):
            _draw_box(ax, first[i], COLORS[i], "--", alpha=0.6,
                      label=f"{names[i]} at first contact, t_i = {t_i:.4f} s")
    boxes, cgs = _vehicle_boxes(inputs, t_x)
    when = ("at the case state (no contact)" if no_contact else f"at the exchange, t = {t_x:.4f} s" if auto
            else "at the case state (explicit contact)")
    for i in range(2):
        _draw_box(ax, boxes[i], COLORS[i], "-", label=f"{names[i]} {when}")

    extent = max(max(float(v.length), float(v.width)) for v in inputs.vehicles)
    v_scale = None
    if not no_contact:
        overlap = clip_polygon(boxes[0], boxes[1])
        if len(overlap) >= 3:
            ax.add_patch(Polygon(overlap, closed=True, facecolor="0.6", edgecolor="0.3", alpha=0.5,
                                 label="overlap of the footprints"))
        p = np.asarray(c.point, float)[:2]
        n3 = np.asarray(c.normal, float)
        n = n3[:2] / max(np.linalg.norm(n3[:2]), 1e-12)
        tang = np.array([-n[1], n[0]])
        half = 0.45 * extent
        ax.plot(*np.stack([p - half * tang, p + half * tang]).T, "-", color="red", lw=1.2, label="contact plane")
        _arrow(ax, p + 0.4 * extent * n, p, dict(arrowstyle="-|>", color="red", lw=1.8), zorder=5)
        ax.plot([], [], color="red", marker=r"$\rightarrow$", ls="", ms=12, label="normal n (from 2 into 1)")
        mu = float(inputs.contact.friction)
        half_angle = math.degrees(math.atan(mu))
        az = math.degrees(math.atan2(n[1], n[0]))
        ax.add_patch(Wedge(p, 0.3 * extent, az - half_angle, az + half_angle, facecolor="tab:cyan", alpha=0.25,
                           edgecolor="tab:blue", label=f"friction cone, mu = {mu:g} (half-angle {half_angle:.1f} deg)"))
        j = np.asarray(c.impulse, float)[:2]
        j_mag = float(np.linalg.norm(j))  # the arrow: the horizontal part
        total = float(c.impulse_magnitude)
        if j_mag > 0:
            k = 0.35 * extent / j_mag  # m per N s
            shown = f"{j_mag:,.0f}"  # where the impulse has a vertical part, the arrow is shorter than it
            vertical = "" if shown == f"{total:,.0f}" else f", horizontal part {shown} N s"
            for i, sign in enumerate((1.0, -1.0)):
                _arrow(ax, p + sign * k * j, p, dict(arrowstyle="-|>", color=COLORS[i], lw=2.5))
                ax.plot([], [], color=COLORS[i], lw=2.5,
                        label=f"impulse on {names[i]}: {total:,.0f} N s ({total / U.LBF_S:,.0f} lbf s){vertical}")
        ax.plot(*p, "kx", ms=9, mew=2, label=f"impulse centroid ({p[0]:.3f}, {p[1]:.3f}) m")

    speeds = []
    for i, v in enumerate(inputs.vehicles):
        speeds.append(float(v.speed))
        speeds.append(float(np.linalg.norm(np.asarray(res.vehicles[i].velocity_after, float)[:2])))
    vmax = max(speeds)
    if vmax > 0:
        v_scale = 0.5 * extent / vmax  # m per m/s
        for i, v in enumerate(inputs.vehicles):
            before = float(v.speed) * np.array([math.cos(float(v.course)), math.sin(float(v.course))])
            after = np.asarray(res.vehicles[i].velocity_after, float)[:2]
            for vec, style, side in ((before, ":", 1.0), (after, "-", -1.0)):
                length = float(np.linalg.norm(vec))
                if length == 0:
                    continue
                # before on the left of the arrow's line, after on its right, so that they never hide
                # each other or the impulse arrows of an inline impact
                shift = side * 0.05 * extent * np.array([-vec[1], vec[0]]) / length
                _arrow(ax, cgs[i] + shift + v_scale * vec, cgs[i] + shift,
                       dict(arrowstyle="-|>", color=COLORS[i], lw=1.3, ls=style))
            ax.plot(*cgs[i], "o", color=COLORS[i], ms=4)
        unit = f"1 m = {1 / v_scale:.2f} m/s = {1 / v_scale / U.MPH:.2f} mph"
        ax.plot([], [], color="0.3", ls=":", label=f"CG velocity before ({unit})")
        ax.plot([], [], color="0.3", ls="-", label=f"CG velocity after ({unit})")
    if no_contact:
        ax.text(0.02, 0.02, "no contact within the search horizon", transform=ax.transAxes, fontsize=8)

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
    from matplotlib.transforms import offset_copy

    below = offset_copy(ax.transAxes, fig=ax.figure, y=-34, units="points")
    ax.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(0.0, 0.0), bbox_transform=below, ncol=2,
              frameon=False)
    return ax


PICTURE_TYPES = (".png", ".pdf", ".svg")


def check_picture_path(path, option="--plot"):
    """Raise CaseError unless matplotlib is installed and ``path`` names a .png, .pdf or .svg file:
    called before anything is solved, so that a bad picture name loses no work."""
    from pathlib import Path

    from .case import CaseError

    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise CaseError(f"{option} needs matplotlib: pip install 'ks-jax[plot]'") from None
    suffix = Path(path).suffix
    if suffix.lower() not in PICTURE_TYPES:
        raise CaseError(f"{option} {path}: unknown picture type '{suffix}' (use .png, .pdf or .svg)")
    from .cli import check_output_file

    check_output_file(path, option)


def save_top_view(solutions, path):
    """Write the top views of one ``Solution`` or a list of them (one panel each) to ``path``
    (PNG, PDF, SVG: by the file name). Returns the path."""
    from matplotlib.figure import Figure  # no pyplot: works without a display, leaves no state

    if not isinstance(solutions, (list, tuple)):
        solutions = [solutions]
    n = len(solutions)
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(8.5 * cols, 9.0 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, sol in zip(axes.flat, solutions):
        top_view(sol, ax)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


# ---------------------------------------------------------------------------------------
# sweeps: maps over one or two swept inputs, histograms of samples


def _bracket(label):
    """' [mph]' for an axis or a title; nothing for a dimensionless quantity."""
    return f" [{label}]" if label else ""


def _categories(output, values):
    """(codes shown, their names) of a bool or status output."""
    from .types import STATUS_TEXT, status_text

    if output == "status":
        codes = np.unique(values).tolist()
        return codes, [STATUS_TEXT.get(c, status_text(c)) for c in codes]
    names = ("stick", "slide") if output.endswith("sliding") else ("False", "True")
    return [0, 1], list(names)


def sweep_view(result, output=None, ax=None, contours=True):
    """Draw one output of a sweep (``ks_jax.sweep``'s ``SweepResult``) in US units on ``ax`` (a new
    figure if None); returns the axes.

    - a grid over one input: the output against it (a line; gaps where a point has no result);
    - a grid over two inputs: a colour map over the first (x) and the second (y), with labelled contour
      lines (``contours``); points without a result are grey;
    - zip samples (e.g. Monte Carlo draws): a histogram with the median and the 5th and 95th percentiles.
    ``contact.sliding`` is drawn as stick / slide and ``"status"`` by its status texts. A sweep with more
    values per axis than ``sweeps.PLOT_LIMITS`` is drawn from every k-th value (``SweepResult.thinned``;
    the title says so). output: an output path of the sweep (default: its first).
    """
    import matplotlib.pyplot as plt

    from .case import CIRCULAR_OUTPUTS, CaseError, input_kind, output_kind, parse_path
    from .report import _deg
    from .sweeps import check_kept

    check_kept(result)
    paths = tuple(result.output_paths) or tuple(p for p in result.outputs if p != "status")
    output = (paths[0] if paths else "status") if output is None else output
    if output not in result.outputs:
        raise CaseError(f"output '{output}' is not among this sweep's results: {', '.join(result.outputs)}")
    if result.mode != "zip" and len(result.axes) > 2:
        raise CaseError(f"a sweep over {len(result.axes)} inputs ({', '.join(result.axes)}) has no picture: "
                        "draw a grid over one or two inputs (sweep the others one value at a time)")
    if not result.strides:
        result = result.thinned()
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 5))
    values, status = np.asarray(result[output]), np.asarray(result["status"])
    categorical = output == "status" or values.dtype == bool
    if categorical:
        codes, names = _categories(output, values)
        shown = np.ma.masked_array(np.searchsorted(codes, values.astype(int)).astype(float),
                                   # a flag means nothing without an exchange (separating, no contact, invalid)
                                   mask=(status != 0) if output != "status" else np.zeros(values.shape, bool))
        scale, unit = 1.0, ""
    else:
        scale, unit = U.US_DISPLAY[output_kind(output)]
        shown = np.ma.masked_invalid(values / scale)
    circular = not categorical and parse_path(output)[2] in CIRCULAR_OUTPUTS
    wrap = (lambda v: v % 360.0) if circular else (lambda v: v)  # noqa: E731
    if circular and shown.count():  # a direction: drawn unwrapped about its circular mean, labelled mod 360
        rad = np.radians(shown.compressed())
        centre = math.degrees(math.atan2(np.mean(np.sin(rad)), np.mean(np.cos(rad))))
        shown = centre + (shown - centre + 180.0) % 360.0 - 180.0
    missing = int(np.count_nonzero(np.ma.getmaskarray(shown)))
    axes = [(p, *U.US_DISPLAY[input_kind(p)], np.asarray(v)) for p, v in result.axes.items()]
    thinned = any(k > 1 for k in result.strides)
    note = [f"shown: 1 in {' x '.join(map(str, result.strides))} points"] if thinned else []
    if result.mode != "zip" and len(axes) == 2 and min(a[3].size for a in axes) == 1:
        # an input with one value is no axis (a map one cell wide draws nothing): a line over the other
        keep = 0 if axes[0][3].size > 1 or axes[1][3].size == 1 else 1
        path, xs, xunit, x = axes[1 - keep]
        note.append(f"{path} = {float(x[0]) / xs:.6g}{_bracket(xunit)}")
        axes = [axes[keep]]
        shown = shown.reshape(-1)
    if missing:
        how = "left out" if result.mode == "zip" else "gaps" if len(result.axes) == 1 else "grey"
        note.append(f"{missing} of {shown.size} points without a result ({how})")
    finite = shown.compressed()
    flat = not categorical and finite.size > 0 and np.ptp(finite) <= 1e-9 * max(1.0, float(np.max(np.abs(finite))))
    if flat:  # one value everywhere (to rounding): say it, no contours of the rounding
        note.append(" ".join(filter(None, (f"{wrap(float(np.median(finite))):.6g}", unit, "everywhere"))))

    if result.mode == "zip":
        data = shown.compressed()
        if categorical:
            counts = np.bincount(data.astype(int), minlength=len(codes))
            ax.bar(range(len(codes)), counts, color="tab:blue")
            ax.set_xticks(range(len(codes)), names)
        elif data.size:
            ax.hist(data, bins=min(60, max(10, int(np.sqrt(data.size)))), color="tab:blue", alpha=0.7)
            for q, style, name in ((50, "-", "median"), (5, "--", "5th percentile"), (95, "--", "95th percentile")):
                x = np.percentile(data, q)
                text = _deg(x, 2) if circular else f"{x:.4g}"
                ax.axvline(x, color="k", ls=style, lw=1.2, label=f"{name} {text} {unit}".rstrip())
            ax.legend(fontsize=8)
        ax.set_xlabel(output + _bracket(unit))
        if circular:
            ax.xaxis.set_major_formatter(lambda v, _: f"{wrap(v):.4g}")
        ax.set_ylabel(f"samples (of {shown.size})")
    elif len(axes) == 1:
        (path, xs, xunit, x), = axes
        ax.plot(x / xs, shown.astype(float).filled(np.nan), "-", marker="o" if x.size <= 60 else None,
                color="tab:blue", ms=3, drawstyle="steps-mid" if categorical else "default")
        ax.set_xlabel(path + _bracket(xunit))
        if categorical:
            ax.set_yticks(range(len(codes)), names)
            ax.set_ylim(-0.5, len(codes) - 0.5)
        ax.set_ylabel(output + _bracket(unit))
        if circular:
            ax.yaxis.set_major_formatter(lambda v, _: f"{wrap(v):.4g}")
        ax.grid(alpha=0.3)
    else:
        (px, xs, xunit, x), (py, ys, yunit, y) = axes
        X, Y = np.meshgrid(x / xs, y / ys, indexing="ij")  # the result's axes: (first path, second path)
        if categorical:
            from matplotlib.colors import ListedColormap

            cmap = ListedColormap([plt.get_cmap("tab10")(i % 10) for i in range(len(codes))]).with_extremes(bad="0.8")
            mesh = ax.pcolormesh(X, Y, shown, shading="auto", cmap=cmap, vmin=-0.5, vmax=len(codes) - 0.5)
            bar = ax.figure.colorbar(mesh, ax=ax, ticks=range(len(codes)))
            bar.ax.set_yticklabels(names)
            bar.set_label(output)
        else:
            cmap = plt.get_cmap("viridis").with_extremes(bad="0.8")
            mesh = ax.pcolormesh(X, Y, shown, shading="auto", cmap=cmap)
            bar = ax.figure.colorbar(mesh, ax=ax, label=output + _bracket(unit))
            if circular:
                bar.ax.yaxis.set_major_formatter(lambda v, _: f"{wrap(v):.4g}")
            if contours and min(X.shape) >= 2 and finite.size and not flat:
                lines = ax.contour(X, Y, shown, levels=8, colors="white", linewidths=0.6,
                                   linestyles="solid" if circular else None)  # 358 deg is not negative
                ax.clabel(lines, fontsize=7, fmt=lambda v: f"{wrap(v):,.0f}" if abs(wrap(v)) >= 100 else f"{wrap(v):.3g}")
        ax.set_xlabel(px + _bracket(xunit))
        ax.set_ylabel(py + _bracket(yunit))
    ax.set_title("\n".join([output + _bracket(unit)] + ([", ".join(note)] if note else [])), fontsize=9)
    return ax


def save_sweep_view(result, path, outputs=None):
    """Write ``sweep_view`` of each of ``outputs`` (default: the sweep's outputs) side by side, three
    per row, to ``path`` (PNG, PDF, SVG: by the file name). Returns the path."""
    from matplotlib.figure import Figure

    outputs = list(outputs or result.output_paths or [p for p in result.outputs if p != "status"] or ["status"])
    if not result.strides:
        result = result.thinned()  # once for every panel
    cols = min(len(outputs), 3)
    rows = math.ceil(len(outputs) / cols)
    fig = Figure(figsize=(6.2 * cols, 4.6 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, output in zip(axes.flat, outputs):
        sweep_view(result, output, ax)
    for ax in list(axes.flat)[len(outputs):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
