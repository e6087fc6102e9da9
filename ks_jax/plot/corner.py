"""A corner plot of posterior draws: each unknown's histogram on the diagonal, each pair's draws below it, with the
Laplace approximation drawn over them (its Gaussian on the diagonal, its 1- and 2-sigma ellipses below), so that
where the two part (a bound, a stick/slide edge, two modes) is seen at a glance."""

from __future__ import annotations

import math
import textwrap

import numpy as np

SIGMA_LEVELS = (1.0, 2.0)  # the Laplace ellipses drawn: the 39% and 86% regions of a 2-D Gaussian
MAX_POINTS = 4000  # draws shown in each pair's scatter (every k-th), enough to see their shape


def corner(fig, samples, labels, estimate=None, covariance=None):
    """Draw the corner plot of ``samples`` (draws, n) on ``fig`` (a matplotlib Figure), one axis label per unknown
    (``labels``, with its unit); ``estimate`` (n,) and ``covariance`` (n, n) in the same units: the Laplace
    approximation drawn over the draws where finite. Returns the (n, n) axes (None above the diagonal).

    A draw with a NaN or an infinite value is left out, and the legend says how many were (matplotlib dropped a NaN
    without a word, and refused the whole picture over an inf); draws none of which is finite are refused."""
    samples = np.asarray(samples, float)
    _check_shapes(samples, labels, estimate, covariance)
    n = samples.shape[1]
    finite = np.all(np.isfinite(samples), axis=1)
    if len(samples) and not finite.any():
        raise ValueError(f"corner: none of the {len(samples)} draws is finite (each holds a NaN or an inf): nothing "
                         "to draw")
    label = "posterior (NUTS)"
    if not finite.all():
        label += f"\n{np.count_nonzero(~finite)} of {len(samples)} draws not finite\n(NaN or inf): left out"
        samples = samples[finite]
    axes = fig.subplots(n, n, squeeze=False)
    thin = samples[:: max(1, math.ceil(len(samples) / MAX_POINTS))]
    est = None if estimate is None else np.asarray(estimate, float)
    cov = None if covariance is None else np.asarray(covariance, float)
    for i in range(n):
        for j in range(n):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(samples[:, i], bins=40, density=True, color="0.6", label=label)
                s = math.sqrt(cov[i, i]) if cov is not None and np.isfinite(cov[i, i]) and cov[i, i] > 0 else None
                if est is not None and s is not None:
                    grid = np.linspace(*ax.get_xlim(), 200)
                    ax.plot(grid, np.exp(-0.5 * ((grid - est[i]) / s) ** 2) / (s * math.sqrt(2 * math.pi)),
                            color="C3", label="Laplace")
                ax.set_yticks([])
            else:
                ax.plot(thin[:, j], thin[:, i], ".", ms=1.5, color="0.4", alpha=0.5)
                block = None if cov is None else cov[np.ix_([j, i], [j, i])]
                if est is not None and block is not None and np.all(np.isfinite(block)):
                    values, vectors = np.linalg.eigh(block)
                    if np.all(values > 0):
                        t = np.linspace(0, 2 * math.pi, 200)
                        for k in SIGMA_LEVELS:
                            ring = vectors @ (k * np.sqrt(values)[:, None] * np.stack([np.cos(t), np.sin(t)]))
                            ax.plot(est[j] + ring[0], est[i] + ring[1], color="C3", lw=1)
            if i == n - 1:
                ax.set_xlabel(labels[j], fontsize="small")
                ax.tick_params(axis="x", labelrotation=45, labelsize="small")
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(labels[i], fontsize="small")
                ax.tick_params(axis="y", labelsize="small")
            elif i > j:
                ax.set_yticklabels([])
    for k in range(n):  # one range per unknown, in its column and its row, so that the panels line up
        spans = [axes[i, k].get_xlim() for i in range(k, n)] + [axes[k, j].get_ylim() for j in range(k)]
        lo, hi = min(a for a, _ in spans), max(b for _, b in spans)
        for i in range(k, n):
            axes[i, k].set_xlim(lo, hi)
        for j in range(k):
            axes[k, j].set_ylim(lo, hi)
    if n:
        axes[0, 0].legend(fontsize="small", loc="upper right")
    return axes


def _check_shapes(samples, labels, estimate, covariance):
    """The draws (draws, n) with n labels, an estimate (n,) and a covariance (n, n) where given: a ValueError
    naming the argument and both shapes, where each failed inside matplotlib or NumPy with an IndexError."""
    if samples.ndim != 2 or not samples.shape[1]:
        raise ValueError(f"corner: samples has shape {samples.shape}: give the draws as (draws, unknowns)")
    n = samples.shape[1]
    if len(labels) != n:
        raise ValueError(f"corner: {len(labels)} labels for {n} unknowns: give one label per column of samples")
    for name, value, shape in (("estimate", estimate, (n,)), ("covariance", covariance, (n, n))):
        if value is not None and np.shape(value) != shape:
            raise ValueError(f"corner: {name} has shape {np.shape(value)}: give {shape} for samples of {n} unknowns")


def save_corner(path, samples, labels, estimate=None, covariance=None, title=None):
    """Write ``corner`` to ``path`` (PNG, PDF or SVG by its name), titled ``title``. Returns the path."""
    from matplotlib.figure import Figure  # no pyplot: works without a display, leaves no state

    samples = np.asarray(samples, float)
    _check_shapes(samples, labels, estimate, covariance)
    n = samples.shape[1]
    fig = Figure(figsize=(2.4 * n + 1.5, 2.4 * n + 1.0))
    corner(fig, samples, labels, estimate, covariance)
    if title:
        fig.suptitle("\n".join(textwrap.wrap(title, int(14 * (2.4 * n + 1.5)))), fontsize="medium")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
