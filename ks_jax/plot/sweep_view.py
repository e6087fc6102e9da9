"""Pictures of a sweep's results over its inputs: a line over one input, a map over two, histograms of
samples (drawn from a thinned view of a large sweep), every output in the one unit system the user chose; a
figure of several outputs says those that do not change over the sweep in one line instead of a panel each."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .. import units as U
from ..case import CIRCULAR_OUTPUTS, input_kind, output_kind, parse_path
from ..case.errors import CaseError, visible
from ..model.types import STATUS_TEXT, status_text
from ..report import angle_text
from ..sweeps import SweepResult, check_kept
from .text import wrap_to_width

CONSTANT_SIZE = 10.0  # points: the line above a figure's panels that says the outputs constant over the sweep


def _bracket(label):
    """' [mph]' for an axis or a title; nothing for a dimensionless quantity."""
    return f" [{label}]" if label else ""


def _categories(output, values):
    """(codes shown, their names) of a bool or status output."""
    if output == "status":
        codes = np.unique(values).tolist()
        return codes, [STATUS_TEXT.get(c, status_text(c)) for c in codes]
    names = ("stick", "slide") if output.endswith("sliding") else ("False", "True")
    return [0, 1], list(names)


def named(path, names=()):
    """A path with the vehicle it is about: ``vehicles[1].speed (Kia K5)``; other paths as they are
    (``"status"``, about no vehicle and no input or output path, too)."""
    if path == "status":
        return path
    group, index = parse_path(path)[:2]
    return f"{path} ({names[index]})" if group == "vehicles" and index is not None and index < len(names) else path


def display_units(result, units="si", typed=None):
    """{path: (SI value of one display unit, label)} for every swept input and output of ``result``: a swept
    input in the unit ``typed`` gives for it (``{input path: unit}``, the units of the values the user typed,
    e.g. ``--over vehicles[1].speed=10km/h:80km/h:8``: its axis reads as typed), every output and every other
    input in the ``units`` system, so that the outputs of one figure are in one system (with ``--units si``
    the delta-V in m/s beside the impulse in N s and the energy in J, whatever unit the speed was typed in)."""
    typed = {p: u for p, u in (typed or {}).items() if u}
    shown = {p: U.display_unit(input_kind(p), units, typed.get(p)) for p in result.axes}
    for p in result.outputs:
        if p != "status" and result.outputs[p].dtype != bool:
            shown[p] = U.display_unit(output_kind(p), units)
    return shown


def constant_text(result, output, shown_in):
    """``output``'s one value as a figure says it ("180 deg", "false (stick)") where it is the same, to
    rounding, at every point of ``result`` that has a result (in the units of ``shown_in``, as
    ``display_units`` gives them; a direction on the circle, 359.99... and 0.00... being one value), else
    None: also where no point has one. ``"status"`` is never constant here (it is drawn when it is all
    there is)."""
    if output == "status":
        return None
    values, status = np.asarray(result[output]), np.asarray(result["status"])
    if values.dtype == bool:
        flags = values[status == 0]  # a flag means nothing without an exchange
        if not flags.size or flags.min() != flags.max():
            return None
        flag = bool(flags[0])
        return f"{str(flag).lower()} ({('stick', 'slide')[flag]})" if output.endswith("sliding") else str(flag).lower()
    scale, unit = shown_in[output]
    finite = values[np.isfinite(values)] / scale
    if not finite.size:
        return None
    circular = parse_path(output)[2] in CIRCULAR_OUTPUTS
    if circular:
        finite = circular_view(np.ma.masked_array(finite))[0].compressed()
    if np.ptp(finite) > 1e-9 * max(1.0, float(np.max(np.abs(finite)))):
        return None
    level = float(f"{float(np.median(finite)):.6g}")  # rounded first: -1e-13 deg reads 0, not 360
    level = (level % 360.0 if circular else level) + 0.0  # + 0.0: no "-0"
    return " ".join(filter(None, (f"{level:.6g}", unit)))


def _undefined_everywhere(result, output) -> bool:
    """Whether ``output`` (a number, not a flag) has no value at any point of ``result`` that was solved: a panel of
    it would be empty (a vehicle's PDOF where it took no part in the exchange)."""
    if output == "status" or output not in result.outputs:
        return False
    values, status = np.asarray(result[output]), np.asarray(result["status"])
    solved = status == 0
    return values.dtype != bool and bool(solved.any()) and not np.isfinite(values[solved]).any()


def circular_view(degrees):
    """Directions (deg; a masked array) as drawn: unwrapped about their circular mean, then, as a whole,
    put where they read as plain numbers: in [0, 360) where they fit there, else in (-180, 180] (a PDOF
    spread about 0 reads -0.4 ... 0.4, not 359.6 ... 0.4). Returns (values, wrapped): ``wrapped`` is True
    where neither range holds them (spread over more than half the circle), and the labels must be read
    mod 360."""
    finite = degrees.compressed()
    if not finite.size:
        return degrees, False
    rad = np.radians(finite)
    centre = math.degrees(math.atan2(np.mean(np.sin(rad)), np.mean(np.cos(rad)))) % 360.0
    shown = centre + (degrees - centre + 180.0) % 360.0 - 180.0
    lo, hi = float(shown.min()), float(shown.max())
    for shift in (0.0, -360.0, 360.0):
        if 0.0 <= lo + shift and hi + shift < 360.0:
            return shown + shift, False
    for shift in (0.0, -360.0, 360.0):
        if -180.0 < lo + shift and hi + shift <= 180.0:
            return shown + shift, False
    return shown, True


class _Panel(NamedTuple):
    """One output of a sweep as its panel draws it (``_panel``)."""

    shown: np.ma.MaskedArray  # the values drawn: in the display unit, or a category's index; masked: no result
    name: str  # the output's path, with its vehicle's name
    unit: str  # the display unit's label ("" for a dimensionless or a categorical output)
    categories: tuple  # (codes, their names) of a bool or status output; () for a number
    circular: bool  # a direction, drawn about its circular mean (``circular_view``)
    wrapped: bool  # directions spread over more than half the circle: the labels read mod 360
    flat: bool  # the same everywhere, to rounding
    span: tuple  # a flat output's scale: whole units about its value
    axes: list  # (path, SI value of one display unit, unit label, values) of each input drawn over
    names: tuple  # the vehicles' names, for the inputs' labels
    note: list  # what the title says under the output's name

    @property
    def title(self):
        """The output's name and unit, as an axis, a colour bar or the title says it."""
        return self.name + _bracket(self.unit)

    def label(self, value):
        """A value as its axis, colour bar or contour says it: mod 360 where the directions are ``wrapped``."""
        return f"{value % 360.0:.4g}" if self.wrapped else f"{value:.4g}"

    def input_label(self, k):
        """The label of the ``k``-th input's axis: its path, vehicle and unit."""
        path, _, unit, _ = self.axes[k]
        return named(path, self.names) + _bracket(unit)


def _check_sweep(result, who):
    """Refuse anything but a sweep's result by its kind: None, say, failed inside with "'NoneType' object has no
    attribute 'outputs'"."""
    if not isinstance(result, SweepResult):
        raise TypeError(f"{who}: a sweep's result (the SweepResult of ks_jax.sweep) is drawn, not a "
                        f"{type(result).__name__}")


def _drawable(result, output):
    """(result, output) as ``sweep_view`` draws them: ``output`` defaulted to the sweep's first and checked
    to be among its results, the sweep checked to have a picture, and ``result`` thinned to
    ``sweeps.PLOT_LIMITS`` unless it is already (``SweepResult.thinned``)."""
    check_kept(result)
    paths = tuple(result.output_paths) or tuple(p for p in result.outputs if p != "status")
    output = (paths[0] if paths else "status") if output is None else output
    if output not in result.outputs:
        raise CaseError(f"output '{output}' is not among this sweep's results: {', '.join(result.outputs)}")
    if result.mode != "zip" and len(result.axes) > 2:
        raise CaseError(f"a sweep over {len(result.axes)} inputs ({', '.join(result.axes)}) has no picture: "
                        "draw a grid over one or two inputs (sweep the others one value at a time)")
    return (result if result.strides else result.thinned()), output


def _shown_values(result, output, shown_in):
    """(values as drawn, unit label, categories) of ``output``: a number in its display unit (``shown_in``);
    a bool or status output as the index of its category (``_categories``), a flag masked where there was
    no exchange. Masked: no result."""
    values, status = np.asarray(result[output]), np.asarray(result["status"])
    if output == "status" or values.dtype == bool:
        codes, names_of_codes = _categories(output, values)
        shown = np.ma.masked_array(np.searchsorted(codes, values.astype(int)).astype(float),
                                   # a flag means nothing without an exchange (separating, no contact, invalid)
                                   mask=(status != 0) if output != "status" else np.zeros(values.shape, bool))
        return shown, "", (codes, names_of_codes)
    scale, unit = shown_in[output]
    return np.ma.masked_invalid(values / scale), unit, ()


def _one_value_axis(result, shown, axes, names, note):
    """A grid over two inputs, one of which has a single value, as a line over the other (a map one cell
    wide draws nothing): (shown, axes) over that one input, the single value said in ``note``."""
    if result.mode == "zip" or len(axes) != 2 or min(a[3].size for a in axes) != 1:
        return shown, axes
    keep = 0 if axes[0][3].size > 1 or axes[1][3].size == 1 else 1
    path, xs, xunit, x = axes[1 - keep]
    note.append(f"{named(path, names)} = {float(x[0]) / xs:.6g}{_bracket(xunit)}")
    return shown.reshape(-1), [axes[keep]]


def _panel(result, output, units, typed):
    """``output`` of ``result`` (thinned already) as its panel draws it (a ``_Panel``), with the notes its
    title carries: the thinning, an input of one value, the points without a result, a value the same
    everywhere, and how directions are drawn."""
    shown_in = display_units(result, units, typed)
    names = tuple(visible(n) for n in getattr(result, "names", ()))
    shown, unit, categories = _shown_values(result, output, shown_in)
    circular = not categories and parse_path(output)[2] in CIRCULAR_OUTPUTS
    wrapped = False
    if circular:
        shown, wrapped = circular_view(shown)
    missing = int(np.count_nonzero(np.ma.getmaskarray(shown)))
    axes = [(p, *shown_in[p], np.asarray(v)) for p, v in result.axes.items()]
    thinned = any(k > 1 for k in result.strides)
    note = [f"shown: 1 in {' x '.join(map(str, result.strides))} points"] if thinned else []
    shown, axes = _one_value_axis(result, shown, axes, names, note)
    if missing:
        how = "left out" if result.mode == "zip" else "gaps" if len(result.axes) == 1 else "grey"
        note.append(f"{missing} of {shown.size} points without a result ({how})")
    finite = shown.compressed()
    flat = not categories and finite.size > 0 and np.ptp(finite) <= 1e-9 * max(1.0, float(np.max(np.abs(finite))))
    level = float(np.median(finite)) if flat else 0.0
    # a value the same everywhere (to rounding) is said, and drawn on a scale of whole units about it, not of
    # its rounding (which read 0.1 ... 0, 360, 359.9 for a PDOF of 0 deg)
    span = (level - max(1.0, 0.01 * abs(level)), level + max(1.0, 0.01 * abs(level)))
    if flat:
        note.append(" ".join(filter(None, (f"{(level % 360.0) if circular else level:.6g}", unit, "everywhere"))))
    if circular and not wrapped and finite.size and (finite.min() < 0 or finite.max() > 360):
        note.append("directions about 0 deg drawn from -180 to 180 deg (-0.4 is 359.6)")
    elif wrapped:
        note.append("directions spread over more than half the circle: labels mod 360")
    return _Panel(shown, named(output, names), unit, categories, circular, wrapped, flat, span, axes, names, note)


def _draw_histogram(ax, panel):
    """Samples (zip): a bar per category, or a histogram with the median and the 5th and 95th
    percentiles (a direction's reported in [0, 360), and where it is drawn if that differs)."""
    data = panel.shown.compressed()
    if panel.categories:
        codes, names_of_codes = panel.categories
        counts = np.bincount(data.astype(int), minlength=len(codes))
        ax.bar(range(len(codes)), counts, color="tab:blue")
        ax.set_xticks(range(len(codes)), names_of_codes)
    elif data.size:
        ax.hist(data, bins=min(60, max(10, int(np.sqrt(data.size)))), color="tab:blue", alpha=0.7,
                range=panel.span if panel.flat else None)
        for q, style, name in ((50, "-", "median"), (5, "--", "5th percentile"), (95, "--", "95th percentile")):
            x = np.percentile(data, q)
            text = f"{name} {angle_text(x, 2) if panel.circular else f'{x:.4g}'} {panel.unit}".rstrip()
            if panel.circular and not panel.wrapped and angle_text(x, 2) != f"{x:.2f}":
                text += f" (drawn at {x:.2f})"
            ax.axvline(x, color="k", ls=style, lw=1.2, label=text)
        ax.legend(fontsize=8)
    ax.set_xlabel(panel.title)
    if panel.circular:
        ax.xaxis.set_major_formatter(lambda v, _: panel.label(v))
    ax.set_ylabel(f"samples (of {panel.shown.size})")


def _draw_line(ax, panel):
    """A grid over one input: the output against it (gaps where a point has no result; steps between
    categories)."""
    (_, xs, _, x), = panel.axes
    ax.plot(x / xs, panel.shown.astype(float).filled(np.nan), "-", marker="o" if x.size <= 60 else None,
            color="tab:blue", ms=3, drawstyle="steps-mid" if panel.categories else "default")
    ax.set_xlabel(panel.input_label(0))
    if panel.categories:
        codes, names_of_codes = panel.categories
        ax.set_yticks(range(len(codes)), names_of_codes)
        ax.set_ylim(-0.5, len(codes) - 0.5)
    elif panel.flat:
        ax.set_ylim(*panel.span)
    ax.set_ylabel(panel.title)
    if panel.circular:
        ax.yaxis.set_major_formatter(lambda v, _: panel.label(v))
    ax.grid(alpha=0.3)


def _draw_map(ax, panel, contours):
    """A grid over two inputs: a colour map over the first (x) and the second (y), points without a result
    grey; a category per colour, or a number on a colour bar with labelled contour lines (``contours``)."""
    import matplotlib.pyplot as plt

    (_, xs, _, x), (_, ys, _, y) = panel.axes
    X, Y = np.meshgrid(x / xs, y / ys, indexing="ij")  # the result's axes: (first path, second path)
    if panel.categories:
        from matplotlib.colors import ListedColormap

        codes, names_of_codes = panel.categories
        cmap = ListedColormap([plt.get_cmap("tab10")(i % 10) for i in range(len(codes))]).with_extremes(bad="0.8")
        mesh = ax.pcolormesh(X, Y, panel.shown, shading="auto", cmap=cmap, vmin=-0.5, vmax=len(codes) - 0.5)
        bar = ax.figure.colorbar(mesh, ax=ax, ticks=range(len(codes)))
        bar.ax.set_yticklabels(names_of_codes)
        bar.set_label(panel.name)
    else:
        cmap = plt.get_cmap("viridis").with_extremes(bad="0.8")
        limits = {"vmin": panel.span[0], "vmax": panel.span[1]} if panel.flat else {}
        mesh = ax.pcolormesh(X, Y, panel.shown, shading="auto", cmap=cmap, **limits)
        bar = ax.figure.colorbar(mesh, ax=ax, label=panel.title)
        if panel.circular:
            bar.ax.yaxis.set_major_formatter(lambda v, _: panel.label(v))
        if contours and min(X.shape) >= 2 and panel.shown.compressed().size and not panel.flat:
            lines = ax.contour(X, Y, panel.shown, levels=8, colors="white", linewidths=0.6,
                               linestyles="solid" if panel.circular else None)  # -2 deg is no negative value
            ax.clabel(lines, fontsize=7, fmt=lambda v: panel.label(v) if panel.circular else
                      f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}")
    ax.set_xlabel(panel.input_label(0))
    ax.set_ylabel(panel.input_label(1))


def sweep_view(result, output=None, ax=None, contours=True, units="si", typed=None):
    """Draw one output of a sweep (``ks_jax.sweep``'s ``SweepResult``) on ``ax`` (a new figure if None);
    returns the axes.

    - a grid over one input: the output against it (a line; gaps where a point has no result);
    - a grid over two inputs: a colour map over the first (x) and the second (y), with labelled contour
      lines (``contours``); points without a result are grey;
    - zip samples (e.g. Monte Carlo draws): a histogram with the median and the 5th and 95th percentiles.
    Units (``display_units``): the ``units`` system ("si": m/s, m, N s, J, kg; "us": mph, ft, lbf s, ft lbf,
    lb; directions in degrees and rates in deg/s in both), except a swept input's axis where ``typed``
    ({input path: unit}, e.g. {"vehicles[1].speed": "km/h"}) gives the unit the user typed; the output is
    always in the ``units`` system. Paths about a vehicle carry its name
    (``vehicles[1].speed (Kia K5)``). Directions (PDOF, course, azimuth) are drawn about their circular mean
    (``circular_view``). ``contact.sliding`` is drawn as stick / slide and ``"status"`` by its status texts.
    A sweep with more values per axis than ``sweeps.PLOT_LIMITS`` is drawn from every k-th value
    (``SweepResult.thinned``; the title says so). output: an output path of the sweep (default: its first).
    """
    import matplotlib.pyplot as plt

    _check_sweep(result, "sweep_view")
    result, output = _drawable(result, output)
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 5))
    panel = _panel(result, output, units, typed)
    if result.mode == "zip":
        _draw_histogram(ax, panel)
    elif len(panel.axes) == 1:
        _draw_line(ax, panel)
    else:
        _draw_map(ax, panel, contours)
    ax.set_title("\n".join([panel.title] + ([", ".join(panel.note)] if panel.note else [])), fontsize=9)
    return ax


def sweep_figure(result, outputs=None, units="si", typed=None):
    """A figure of ``sweep_view`` of each of ``outputs`` (default: the sweep's outputs) side by side, three
    per row, in ``units`` and the ``typed`` units (as ``sweep_view``; every output in the one system
    ``units``). An output that is the same at every point with a result (``constant_text``: an inline
    impact's PDOF of 180 deg, a contact that sticks everywhere) gets no panel: one line above the panels
    says each with its value ("constant over the sweep: vehicles[0].pdof (Lucid Air) = 180 deg, ..."; "over
    the points drawn" where ``result`` holds a thinned sweep's points only). An output undefined at every solved
    point (a PDOF where no impulse reached the vehicle) gets no panel either, and the line names it. Where every
    output is constant or undefined, each has its panel. Returns the figure (matplotlib's ``Figure``)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    _check_sweep(result, "sweep_figure")
    outputs = list(outputs or result.output_paths or [p for p in result.outputs if p != "status"] or ["status"])
    check_kept(result)
    shown_in = display_units(result, units, typed)
    constant = {p: constant_text(result, p, shown_in) for p in outputs if p in result.outputs}
    nowhere = [p for p in outputs if _undefined_everywhere(result, p)]
    drawn = [p for p in outputs if constant.get(p) is None and p not in nowhere] or outputs
    names = tuple(visible(n) for n in getattr(result, "names", ()))
    said = [f"{named(p, names)} = {constant[p]}" for p in outputs if p not in drawn and p not in nowhere]
    over = "the points drawn" if any(k > 1 for k in result.strides) else "the sweep"
    lines = [f"constant over {over}: {', '.join(said)}"] if said else []
    if drawn != outputs and nowhere:  # a vehicle not in the exchange has no PDOF at any point: no empty panel
        lines.append(f"undefined over {over}: {', '.join(named(p, names) for p in nowhere)}")
    if not result.strides:
        result = result.thinned()  # once for every panel
    cols = min(len(drawn), 3)
    rows = math.ceil(len(drawn) / cols)
    fig = Figure(figsize=(6.2 * cols, 4.6 * rows))
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, output in zip(axes.flat, drawn):
        sweep_view(result, output, ax, units=units, typed=typed)
    for ax in list(axes.flat)[len(drawn):]:
        ax.set_visible(False)
    if lines:
        fig.suptitle("\n".join(wrap_to_width(line, 0.96 * 72.0 * fig.get_figwidth(), CONSTANT_SIZE, indent="")
                               for line in lines), fontsize=CONSTANT_SIZE)
    fig.tight_layout()
    return fig


def save_sweep_view(result, path, outputs=None, units="si", typed=None):
    """Write ``sweep_figure`` of ``outputs`` (default: the sweep's outputs) to ``path`` (PNG, PDF, SVG: by the
    file name), in ``units`` and the ``typed`` units (as ``sweep_view``). Returns the path."""
    _check_sweep(result, "save_sweep_view")
    sweep_figure(result, outputs, units=units, typed=typed).savefig(path, dpi=110)
    return path
