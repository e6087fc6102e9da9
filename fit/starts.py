"""Where a fit's starts begin: the given start (or the middle of the bounds) and a Latin hypercube within the
bounds, or normal draws about the first start where a bound is missing."""

from __future__ import annotations

import numpy as np

from ks_jax.case import input_kind


# the least spread (SI) of the starts of an unknown without two bounds, by its kind: a speed of 0 with
# starts within +-1 m/s of it would all stay where the vehicles do not collide
START_SPREAD = {"velocity": 10.0, "angular_velocity": 0.5, "angle": 0.5, "length": 1.0, "time": 0.05,
                "mass": 300.0, "inertia": 500.0}


def starts(paths, lower, upper, start, prior_mean, prior_sigma, current, n_starts: int, rng) -> np.ndarray:
    """(B, S, n) starts in x (SI) of B fits of the unknowns at ``paths`` (n): the first at each unknown's start
    (else the middle of its bounds, else the case value), the others a Latin hypercube within the bounds (2%
    margins), or normal draws around the first start where a bound is missing (spread: the prior's sigma,
    else |first start|, at least ``START_SPREAD`` of its kind).

    lower, upper (B, n): bounds (+-inf for none); start, prior_mean, prior_sigma (B, n): NaN where none;
    current (B, n): the case's values. The draws go unknown by unknown, every fit's draws of one unknown at
    once (one fit's are those it drew alone before fits were drawn as a batch)."""
    lower, upper, start, prior_mean, prior_sigma, current = (
        np.asarray(a, np.float64) for a in (lower, upper, start, prior_mean, prior_sigma, current))
    B, n = lower.shape
    k = n_starts - 1
    x0 = np.empty((B, n_starts, n))
    for j in range(n):
        lo, hi = lower[:, j], upper[:, j]
        both = np.isfinite(lo) & np.isfinite(hi)
        with np.errstate(invalid="ignore"):  # inf - inf where a bound is missing: those are drawn below
            first = np.where(np.isnan(start[:, j]), 0.5 * (lo + hi), start[:, j])
        if (b := np.flatnonzero(both)).size:
            strata = (rng.permuted(np.tile(np.arange(k), (b.size, 1)), axis=1) + rng.random((b.size, k))) / max(k, 1)
            x0[b, 1:, j] = lo[b, None] + (hi - lo)[b, None] * (0.02 + 0.96 * strata)  # Latin hypercube in [0, 1)
        if (u := np.flatnonzero(~both)).size:
            lo_u, hi_u = lo[u], hi[u]
            f = np.where(~np.isnan(start[u, j]), start[u, j],
                         np.where(~np.isnan(prior_mean[u, j]), prior_mean[u, j], current[u, j]))
            f = np.where(np.isfinite(lo_u), np.maximum(f, lo_u + 1e-3), f)
            f = np.where(np.isfinite(hi_u), np.minimum(f, hi_u - 1e-3), f)
            s = np.where(~np.isnan(prior_sigma[u, j]), prior_sigma[u, j],
                         np.maximum(np.abs(f), START_SPREAD.get(input_kind(paths[j]), 1.0)))
            draws = f[:, None] + s[:, None] * rng.standard_normal((u.size, k))
            has_lo, has_hi = np.isfinite(lo_u)[:, None], np.isfinite(hi_u)[:, None]
            lo_0, hi_0 = np.where(has_lo, lo_u[:, None], 0.0), np.where(has_hi, hi_u[:, None], 0.0)
            draws = np.where(has_lo, lo_0 + np.abs(draws - lo_0), draws)  # reflected into the bounds
            draws = np.where(has_hi, hi_0 - np.abs(hi_0 - draws), draws)
            x0[u, 1:, j] = draws
            first[u] = f
        x0[:, 0, j] = first
    return x0


def first_starts(paths, arrays, n_starts, rng) -> np.ndarray:
    """``starts`` in the fit's coordinates (moved as ``arrays``, a ``FitArrays``: one fit's (n,) or a batch's
    (B, n)): (S, n) or (B, S, n)."""
    one = np.ndim(arrays.lower) == 1
    lift = (lambda a: np.asarray(a)[None]) if one else np.asarray
    x = starts(paths, *map(lift, (arrays.lower, arrays.upper, arrays.start, arrays.prior_mean, arrays.prior_sigma,
                                  arrays.current)), n_starts, rng) - lift(arrays.x_offset)[:, None]
    return x[0] if one else x
