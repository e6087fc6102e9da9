"""Monte Carlo refits: the evidence perturbed by its sigmas and the priors' means by theirs, refitted through the
fit's own compiled program, and notes where the refits contradict the linearised (Laplace) standard errors."""

from __future__ import annotations

import math

import numpy as np

from ks_jax.progress import Progress

from .problem import to_z
from .report import linearisation_note
from .rows import best_start, run_rows, stack
from .starts import first_starts

PERCENTILES = (5, 50, 95)


MC_CHECK_SAMPLES = 100  # fewer refits say too little: at 32, Gaussian refits of a linear fit crossed the bounds


# below in 3.0% of unknowns (about one 6-unknown fit in six), at 64 in 0.14%, at 100 in 0.009% (200,000 draws of
# N standard normal refits each, NumPy's percentiles)
MC_SPREAD_RATIO = 1.6  # Monte Carlo 5-95% spread over 2 x 1.645 sigma: outside [1/1.6, 1.6] is a note


MC_MEDIAN_SHIFT = 0.5  # |Monte Carlo median - estimate| in sigmas above which it is a note


def linearisation_notes(result) -> list:
    """Where the Monte Carlo refits contradict the linearised (Laplace) standard error of a determined
    unknown: a 5-95% spread more than MC_SPREAD_RATIO times wider or narrower than +/- 1.645 sigma, or
    a median more than MC_MEDIAN_SHIFT sigma from the estimate. Then the results are not linear in
    that unknown over its uncertainty (or a bound cuts the refits off), and the standard error
    misleads."""
    mc = result.monte_carlo
    if mc is None or mc["samples"] < MC_CHECK_SAMPLES:
        return []
    notes = []
    for u in result.unknowns:
        s = result.std[u.path]
        if u.path in result.not_determined or not (math.isfinite(s) and s > 0):
            continue
        p5, p50, p95 = (mc["percentiles"][q][u.path] for q in ("5", "50", "95"))
        ratio = (p95 - p5) / (2 * 1.645 * s)
        shift = (p50 - result.estimate[u.path]) / s
        if 1 / MC_SPREAD_RATIO <= ratio <= MC_SPREAD_RATIO and abs(shift) <= MC_MEDIAN_SHIFT:
            continue
        notes.append(linearisation_note(u.path, result.estimate[u.path], s, p5, p50, p95))
    return notes


def refit_perturbed(problem, solver, max_iter, a, unknowns, z_best, starts, samples, rng, smoothing, dtype, progress,
                    chunk, block, devices=None, everywhere=True):
    """Refit ``samples`` copies of the evidence of one case (``a``: its ``FitArrays.row``), each perturbed by
    N(0, sigma^2), and of each Gaussian prior's mean, perturbed by N(0, prior sigma^2). Calls of ``block`` rows, on
    ``devices`` (``rows.run_rows``).

    Where to start each refit: ``everywhere`` (the fit's own starts ended in more than one minimum:
    ``rows.several_minima``), from ``starts`` starts, the first at the estimate and the others drawn as for the
    fit, so that a refit whose perturbed evidence prefers another minimum can find it. Otherwise from the
    estimate alone, the perturbed problem's minimum being the one the estimate lies in, and again from every
    start where that did not converge: a fit whose starts all ended at one cost found one minimum in the bounds.

    A prior is a measurement of its unknown like any evidence (the fit weighs its mean by its sigma as it weighs
    a measured value), so the parametric bootstrap draws it again too: refits with the priors held fixed would
    spread only by the evidence's share of the uncertainty, narrower than the Laplace standard error by the
    prior's share, and most where the prior dominates. With both drawn, the refits of a problem linear over its
    uncertainty spread as its Laplace covariance (J^T W J + P)^-1."""
    n_mc = int(samples)
    noise = rng.standard_normal((n_mc, len(a.values)))
    values = a.values + a.sigmas * noise
    has_prior = a.pw > 0
    prior_means = np.repeat(a.pm[None], n_mc, 0)
    if has_prior.any():  # drawn only where there are priors: the draws of a fit without them are as they were
        prior_sigma = np.where(has_prior, 1.0 / np.where(has_prior, a.pw, 1.0), 0.0)
        prior_means = prior_means + prior_sigma * rng.standard_normal((n_mc, len(a.pm)))
    paths = [u.path for u in unknowns]
    x0 = np.stack([first_starts(paths, a, starts, rng) for _ in range(n_mc)])
    z0 = np.stack([to_z(x, a.lo, a.hi) for x in x0])
    z0[:, 0] = z_best
    bar = Progress(n_mc, "monte carlo", "fit") if progress else None

    def refit(which, z_starts, count):
        """The best start's x and convergence of the refits ``which``, each from its ``z_starts`` (k, S, n)."""
        size = min(chunk, len(which)) if progress else len(which)
        xs, conv = [], []
        for s in range(0, len(which), size):
            rows = which[s:s + size]
            k = len(rows)
            sigmas, lo, hi, pw = (np.repeat(v[None], k, 0) for v in (a.sigmas, a.lo, a.hi, a.pw))
            out = run_rows(problem, solver, max_iter, stack([a.inputs] * k), values[rows], sigmas, lo, hi,
                           prior_means[rows], pw, z_starts[s:s + k], smoothing, dtype, z_starts.shape[1], block,
                           devices)
            best = best_start(out.cost, out.converged)
            xs.append(out.x[np.arange(k), best])
            conv.append(out.converged[np.arange(k), best])
            if count and bar is not None:
                bar.update(k)
        return np.concatenate(xs), np.concatenate(conv)

    everyone = np.arange(n_mc)
    if everywhere:
        xs, conv = refit(everyone, z0, True)
    else:
        xs, conv = refit(everyone, z0[:, :1], True)
        again = np.flatnonzero(~conv)
        if again.size:
            xs[again], conv[again] = refit(again, z0[again], False)
    if bar is not None:
        bar.close()
    xs = xs + a.x_offset
    use = xs[conv] if conv.any() else xs
    pct = {str(p): {path: float(v) for path, v in zip(paths, np.percentile(use, p, axis=0))} for p in PERCENTILES}
    return {"samples": n_mc, "converged_fraction": float(conv.mean()), "percentiles": pct, "x": xs, "converged": conv}
