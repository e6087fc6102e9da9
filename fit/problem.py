"""What a fit compiles (docs/fit.md): ``Problem``, the static (hashable) part that the jitted solver is
specialised on, made from the checked unknowns and evidence (``fit.spec``); and ``residuals``, the pure,
unbatched residual function

    r = [ (wrap(pred_k - value_k)) / sigma_k  for each evidence k ]
        ++ [ (x_j - prior_mean_j) / prior_sigma_j  for each unknown j (0 without a prior) ]

so that the fit minimises 0.5 |r|^2 (weighted least squares with Gaussian priors). Angles are
compared on the circle: the difference is wrapped to [-180, 180) degrees ([-pi, pi) rad).

Bounds are enforced by smooth transforms of an unconstrained z (``to_x``):
both bounds: x = lo + (hi - lo) sigmoid(z); only a lower bound: x = lo + softplus(z);
only an upper bound: x = hi - softplus(-z); none: x = z.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ks_jax.backend import Plan
from ks_jax.case import Motion, get_input, get_output, input_ties, set_input
from ks_jax.solve import solve_inputs


@dataclass(frozen=True)
class Problem:
    """The static part of a fit (hashable; the jitted solver is specialised on it).

    unknowns: input paths; ties: (unknown index, extra input path set to the same value)
    (a fitted yaw also moves the course when the case gives no course); evidence: tuples
    (path, is_output, period) with period 360 (degrees), 2 pi (rad) or 0 (not an angle). plan: how its rows are
    computed (``ks_jax.backend.Plan``; set by ``reconstruct_batch`` from its devices; None: JAX's default devices'
    path)."""

    unknowns: tuple
    ties: tuple
    evidence: tuple
    auto_point: bool = False
    auto_normal: bool = False
    pole: bool = False  # vehicle 2 is a pole (``Case.pole``)
    motion: Motion | None = None  # the vehicles move on to rest (``Case.motion``)
    between: tuple = (0, 1)  # the first exchange's bodies (``Case.between``)
    plan: Plan | None = None

    @property
    def n(self) -> int:
        return len(self.unknowns)

    @property
    def m(self) -> int:
        return len(self.evidence)


def to_x(z, lo, hi):
    """Unconstrained z (n,) -> x (n,) within [lo, hi] (smooth, see the module docstring)."""
    lo_f, hi_f = jnp.isfinite(lo), jnp.isfinite(hi)
    lo0, hi0 = jnp.where(lo_f, lo, 0.0), jnp.where(hi_f, hi, 0.0)
    # the sigmoid from whichever bound is nearer, so that x - lo or hi - x (and dx/dz) keep
    # their relative precision as z saturates (1 - sigmoid(z) would cancel to 0)
    w = hi0 - lo0
    both = jnp.where(z < 0, lo0 + w * jax.nn.sigmoid(z), hi0 - w * jax.nn.sigmoid(-z))
    lower = lo0 + jax.nn.softplus(z)
    upper = hi0 - jax.nn.softplus(-z)
    return jnp.where(lo_f & hi_f, both, jnp.where(lo_f, lower, jnp.where(hi_f, upper, z)))


def to_z(x, lo, hi):
    """Inverse of ``to_x`` (NumPy, float64); x is clipped a hair inside finite bounds."""
    x, lo, hi = (np.asarray(a, dtype=np.float64) for a in (x, lo, hi))
    lo_f, hi_f = np.isfinite(lo), np.isfinite(hi)
    w = np.where(lo_f & hi_f, hi - lo, 1.0)
    with np.errstate(all="ignore"):
        f = np.clip((x - np.where(lo_f, lo, 0)) / w, 1e-9, 1 - 1e-9)
        both = np.log(f) - np.log1p(-f)
        dl = np.maximum(x - np.where(lo_f, lo, 0), 1e-9)
        lower = np.where(dl > 30, dl, np.log(np.expm1(np.minimum(dl, 30))))
        du = np.maximum(np.where(hi_f, hi, 0) - x, 1e-9)
        upper = -np.where(du > 30, du, np.log(np.expm1(np.minimum(du, 30))))
    return np.where(lo_f & hi_f, both, np.where(lo_f, lower, np.where(hi_f, upper, x)))


def apply_unknowns(problem: Problem, inputs, x):
    for path, xi in zip(problem.unknowns, x):
        inputs = set_input(inputs, path, xi)
    for i, path in problem.ties:
        inputs = set_input(inputs, path, x[i])
    return inputs


def case_at(case, values: dict, name: str | None = None):
    """``case`` with its inputs at ``values`` (path -> SI: a fit's ``estimate``, or any scalar inputs), and the
    inputs tied to them moved with them (a course that follows its yaw, ``ks_jax.case.input_ties``), as a fit
    solves it; named ``name`` where one is given. ``ks_jax.solve`` of it is the case at a fit's estimate."""
    paths = tuple(values)
    inputs = apply_unknowns(Problem(paths, input_ties(case, paths), ()), case.inputs, [values[p] for p in paths])
    return dataclasses.replace(case, inputs=inputs, name=case.name if name is None else name)


def predict(problem: Problem, inputs, x, smoothing):
    """(predicted evidence (m,), (status (), sliding (), |J_t| / J_n ())) for unknowns x (n,), SI / the
    result's units. |J_t| / J_n of a contact that sticks is the least friction that keeps it sticking."""
    inputs = apply_unknowns(problem, inputs, x)
    res = solve_inputs(inputs, problem.auto_point, problem.auto_normal, smoothing, problem.pole, problem.motion,
                       problem.between, problem.plan)
    preds = [get_output(res, p) if is_out else get_input(inputs, p) for p, is_out, _ in problem.evidence]
    dtype = jnp.result_type(x)
    c = res.contact
    pushed = c.impulse_normal > 0
    ratio = jnp.where(pushed, c.impulse_tangential / jnp.where(pushed, c.impulse_normal, 1), 0)
    return jnp.stack([jnp.asarray(p, dtype) for p in preds]), (c.status, c.sliding, ratio)


def wrap(d, period):
    """Angle differences to [-period/2, period/2) (period 0: unchanged)."""
    if period == 0:
        return d
    return jnp.mod(d + 0.5 * period, period) - 0.5 * period


def residuals(problem: Problem, x, inputs, values, sigmas, prior_mean, prior_weight, smoothing):
    """Whitened residuals (m + n,): evidence in sigmas, then priors (0 where none)."""
    pred, _ = predict(problem, inputs, x, smoothing)
    d = jnp.stack([wrap(pred[k] - values[k], period) for k, (_, _, period) in enumerate(problem.evidence)])
    return jnp.concatenate([d / sigmas, (x - prior_mean) * prior_weight])
