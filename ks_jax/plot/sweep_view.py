"""Pictures of a sweep's results over its inputs: a line over one input, a map over two, histograms of
samples (drawn from a thinned view of a large sweep)."""

from __future__ import annotations

import math

import numpy as np

from .. import units as U
from ..case import CIRCULAR_OUTPUTS, input_kind, output_kind, parse_path
from ..case.errors import CaseError
from ..model.types import STATUS_TEXT, status_text
from ..report import angle_text
from ..sweeps import check_kept


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
                text = angle_text(x, 2) if circular else f"{x:.4g}"
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
