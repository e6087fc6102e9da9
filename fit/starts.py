"""Where a fit's starts begin: the given start (or the middle of the bounds) and a Latin hypercube within the
bounds, or normal draws about the first start where a bound is missing."""

from __future__ import annotations

import math

import numpy as np

from ks_jax.case import input_kind


# the least spread (SI) of the starts of an unknown without two bounds, by its kind: a speed of 0 with
# starts within +-1 m/s of it would all stay where the vehicles do not collide
START_SPREAD = {"velocity": 10.0, "angular_velocity": 0.5, "angle": 0.5, "length": 1.0, "time": 0.05,
                "mass": 300.0, "inertia": 500.0}


def starts(unknowns, inputs_value, n_starts: int, rng) -> np.ndarray:
    """(S, n) starts in x (SI): the first at each unknown's start (else the middle of its
    bounds, else the case value), the others a Latin hypercube within the bounds (2% margins),
    or normal draws around the first start where a bound is missing (spread: the prior's sigma,
    else |first start|, at least ``START_SPREAD`` of its kind)."""
    n = len(unknowns)
    x0 = np.empty((n_starts, n))
    k = n_starts - 1
    for j, u in enumerate(unknowns):
        lo, hi = u.lower, u.upper
        base = inputs_value[j]
        if math.isfinite(lo) and math.isfinite(hi):
            first = 0.5 * (lo + hi) if u.start is None else u.start
            strata = (rng.permutation(k) + rng.random(k)) / max(k, 1)  # Latin hypercube in [0, 1)
            draws = lo + (hi - lo) * (0.02 + 0.96 * strata)
        else:
            first = u.start if u.start is not None else (u.prior[0] if u.prior else base)
            if math.isfinite(lo):
                first = max(first, lo + 1e-3)
            if math.isfinite(hi):
                first = min(first, hi - 1e-3)
            s = u.prior[1] if u.prior else max(abs(first), START_SPREAD.get(input_kind(u.path), 1.0))
            draws = first + s * rng.standard_normal(k)
            if math.isfinite(lo):
                draws = lo + np.abs(draws - lo)
            if math.isfinite(hi):
                draws = hi - np.abs(hi - draws)
        x0[0, j] = first
        x0[1:, j] = draws
    return x0


def first_starts(unknowns, arrays, n_starts, rng) -> np.ndarray:
    """``starts`` in the fit's coordinates (moved as ``arrays``)."""
    return starts(unknowns, arrays["current"], n_starts, rng) - arrays["x_offset"]
