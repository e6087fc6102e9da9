"""Uncertainty at the optimum: Laplace covariance, what the evidence does not determine, in words.

Everything here is NumPy, after the jitted fit, on a batch of fits of the same unknowns (small n x n
matrices, decomposed in one batched call each).

Covariance. With J the Jacobian of the whitened residuals (evidence rows and prior rows) with
respect to the *physical* unknowns x at the optimum, the Gauss-Newton (Laplace) covariance is
C = (J^T J)^-1 = (J_ev^T J_ev + P)^-1, P = diag(1/prior_sigma^2). This is exactly the delta-method
image of the covariance in the unconstrained z of the bound transforms (J_z = J_x D with
D = diag(dx/dz), so D (J_z^T J_z)^-1 D = (J_x^T J_x)^-1); computing it in x avoids dividing by
D where a transform saturates at a bound.

Identifiability. Columns are scaled by each unknown's range s_j (the bound width; else the prior
sigma; else max(|x_j|, 1) SI) so that singular values compare like with like. A right singular
vector v of J_ev S with singular value sigma_i <= RTOL * sigma_max (RTOL = 1e-6 in float64,
1e-3 in float32: the evidence then pins that combination a million times more loosely than the
best-determined one) is a direction the evidence does not determine: moving the unknowns by
S v changes no evidence to first order. Each such direction is said in words from its components
(in the reconstructionist's units), after turning the null space into a sparse basis (reduced
row echelon form) so that each sentence names few unknowns. If the priors fix the direction, the
sentence says so and the standard errors stay finite (they are then the priors'). Otherwise
every unknown with a component >= INVOLVED of the largest in a null direction gets std = inf
(null in JSON) and no correlations: the evidence cannot know it, so no confident number is given.
The other standard errors come from the pseudo-inverse on the determined subspace.

Also flagged: unknowns whose standard error is wider than a uniform guess within their bounds
((hi - lo) / sqrt 12: "poorly determined"), and unknowns pinned at a bound (within 1e-4 of the
bound width: the bound, not the evidence, sets them; their Laplace std ignores the bound).
"""

from __future__ import annotations

import math

import numpy as np

from ks_jax import units as U
from ks_jax.case import input_kind

INVOLVED = 0.01
AT_BOUND = 1e-4

# display units: kind -> (unit name, SI per unit, step used in sentences, in display units)
DISPLAY = {
    "velocity": ("mph", U.MPH, 1.0),
    "length": ("ft", U.FT, 1.0),
    "angle": ("deg", U.DEG, 1.0),
    "angular_velocity": ("deg/s", U.DEG_S, 1.0),
    "time": ("s", 1.0, 0.01),
    "mass": ("lb", U.LB, 100.0),
    "inertia": ("kg m^2", 1.0, 100.0),
    "dimensionless": ("", 1.0, 0.01),
    "degrees": ("deg", 1.0, 1.0),
    "impulse": ("lbf s", U.LBF_S, 10.0),
    "energy": ("ft lbf", U.FT_LBF, 100.0),
    "force": ("lbf", U.LBF, 10.0),
}
SI_NAME = {"velocity": "m/s", "length": "m", "angle": "rad", "angular_velocity": "rad/s", "time": "s",
           "mass": "kg", "inertia": "kg m^2", "dimensionless": "", "degrees": "deg", "impulse": "N s",
           "energy": "J", "force": "N"}


CHI2_Z = 2.326  # the standard normal's 99% quantile: a chi^2 above its 99% quantile is a note


def chi2_quantile(dof: int, z: float) -> float:
    """The chi^2 distribution's quantile at the normal quantile z, by Wilson and Hilferty's cube-root
    approximation (within 1% of the exact 99% quantile from 1 degree of freedom up: 6.58 for 6.63)."""
    a = 2.0 / (9.0 * np.asarray(dof, np.float64))
    return dof * (1.0 - a + z * np.sqrt(a)) ** 3


def default_rtol(dtype) -> float:
    return 1e-6 if np.finfo(dtype).eps < 1e-10 else 1e-3


def fmt(x_si: float, kind: str, digits: int = 4, si: bool = False) -> str:
    """A value in the reconstructionist's unit, e.g. '20.01 mph'; with si=True also '(8.944 m/s)'."""
    if x_si is None or not math.isfinite(x_si):
        return "not determined" if x_si is None or math.isinf(x_si) else "nan"
    name, scale, _ = DISPLAY.get(kind, ("", 1.0, 1.0))
    text = _number(x_si / scale, digits) + (f" {name}" if name else "")
    if si and SI_NAME.get(kind, "") != name:
        text += f" ({_number(x_si, digits)}{' ' + SI_NAME[kind] if SI_NAME.get(kind) else ''})"
    return text


def _number(v: float, digits: int) -> str:
    """``digits`` significant digits; 0 for a value within rounding of 0 (a speed at its bound of 0 is
    1e-16 m/s), whole numbers with thousands separators from 10^digits on (89,798 ft lbf, not 8.98e+04), and
    powers of ten from 1e15 on (a value far beyond any crash, shown so that its size can be read)."""
    if abs(v) < 1e-9:
        return "0"
    if abs(v) >= 1e15:
        return f"{v:.{digits}g}"
    if abs(v) >= 10**digits:
        return f"{v:,.0f}"
    return f"{v:.{digits}g}"


def scales(lo, hi, prior_sigma, x) -> np.ndarray:
    """Typical range s_j of each unknown (SI) for scaling the Jacobian's columns: the bound width, else the
    prior's sigma (NaN where none), else max(|x_j|, 1). Arrays of one shape, elementwise."""
    width = hi - lo
    return np.where(np.isfinite(width), width, np.where(np.isfinite(prior_sigma), prior_sigma,
                                                        np.maximum(np.abs(x), 1.0)))


def _rref_basis(N: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """A sparse basis of span(N) (columns n x k): reduced row echelon form of N^T, pivots chosen
    by the largest remaining entry, each vector scaled to a largest component of 1."""
    A = np.array(N.T, dtype=np.float64)  # k x n
    k, n = A.shape
    used = []
    for i in range(k):
        cols = [c for c in range(n) if c not in used]
        c = max(cols, key=lambda c: np.max(np.abs(A[i:, c])))
        r = i + int(np.argmax(np.abs(A[i:, c])))
        A[[i, r]] = A[[r, i]]
        A[i] /= A[i, c]
        for j in range(k):
            if j != i:
                A[j] -= A[j, c] * A[i]
        used.append(c)
    A[np.abs(A) < tol] = 0.0
    return (A / np.max(np.abs(A), axis=1, keepdims=True)).T


def describe_direction(paths, v_scaled: np.ndarray, scale: np.ndarray, prior_paths: list[str]) -> str:
    """Words for a null direction v (in scaled units) of the unknowns at ``paths``: which move together, by how
    much."""
    d = v_scaled * scale  # SI
    big = np.abs(v_scaled) >= INVOLVED * np.max(np.abs(v_scaled))
    idx = [j for j in range(len(paths)) if big[j]]  # in the user's order; the first is the reference
    names = [paths[j] for j in idx]
    if len(idx) == 1:
        text = (f"{names[0]} is not determined by the evidence: changing it changes none of the evidence "
                "(to first order)")
    else:
        ref = idx[0]
        kind = input_kind(paths[ref])
        _, unit_si, step = DISPLAY.get(kind, ("", 1.0, 1.0))
        factor = step * unit_si / abs(d[ref])
        parts = []
        for j in idx:
            amount = d[j] * factor * np.sign(d[ref])
            verb = "raising" if amount > 0 else "lowering"
            parts.append(f"{verb} {paths[j]} by {fmt(abs(amount), input_kind(paths[j]), 3)}")
        listing = ", ".join(names[:-1]) + f" and {names[-1]}"
        text = (f"{listing} are not determined separately: {parts[0]} while " + ", ".join(parts[1:])
                + " changes none of the evidence (to first order); the evidence fixes only a combination of them")
    if prior_paths:
        text += f". Only the prior on {', '.join(prior_paths)} fixes this"
    return text


def one(info: dict, i: int) -> dict:
    """Row ``i`` of ``analyse_batch``'s dict (arrays are views: editing them edits the batch's)."""
    return {k: v[i] for k, v in info.items()}


def analyse_batch(paths, x, J, m: int, lo, hi, prior_sigma, prior_weight, rtol: float) -> dict:
    """Covariance and identifiability at the optimum of B fits of the same unknowns, in NumPy's batched
    linear algebra (one decomposition call for all rows, not one per fit).

    paths: the n unknowns' input paths; x (B, n) SI; J (B, m + n, n): d(whitened residuals)/dx; m: number of
    evidence rows; lo, hi (B, n): the unknowns' bounds (SI, +-inf for none); prior_sigma (B, n) (NaN where
    none); prior_weight (B, n): 1/prior sigma or 0; rtol: relative singular-value threshold. Returns a dict
    with cov (B, n, n) (inf rows/cols for undetermined unknowns), std (B, n), corr (B, n, n) (nan where
    undefined), singular (B, n) (singular values of the scaled evidence Jacobian), undetermined (B, n) bool,
    poorly (B, n) bool (a standard error wider than a uniform guess within the bounds), and per row lists of
    str: statements, at_bound.
    """
    x, J, lo, hi, ps, pw = (np.asarray(a, np.float64) for a in (x, J, lo, hi, prior_sigma, prior_weight))
    B, n = x.shape
    s_j = scales(lo, hi, ps, x)
    Js = J[:, :m] * s_j[:, None, :]
    bad = ~np.all(np.isfinite(Js), axis=(1, 2))
    Js = np.where(bad[:, None, None], 0.0, Js)  # decomposed as zeros, then reported as NaN
    _, sv, Vt = np.linalg.svd(Js, full_matrices=True)
    sv_full = np.zeros((B, n))
    sv_full[:, : sv.shape[1]] = sv
    smax = sv_full.max(axis=1)
    null = np.where((smax > 0)[:, None], sv_full <= rtol * smax[:, None], True)
    p = (pw * s_j) ** 2
    H = np.swapaxes(Js, 1, 2) @ Js + p[:, :, None] * np.eye(n)
    lam, Q = np.linalg.eigh(H)
    cut = np.where(smax > 0, (rtol * smax) ** 2, 0.0)
    cut = np.maximum(cut, rtol**2 * np.maximum(lam.max(axis=1), p.max(axis=1)))
    keep = lam > cut[:, None]
    rows = np.abs(Q)
    share = rows / rows.max(axis=1, keepdims=True)  # each eigenvector's components against its largest
    undetermined = np.where(~keep[:, None, :], share, -np.inf).max(axis=2) >= INVOLVED
    w = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0)
    cov = ((Q * w[:, None, :]) @ np.swapaxes(Q, 1, 2)) * (s_j[:, :, None] * s_j[:, None, :])
    std = np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))
    std = np.where(undetermined, np.inf, std)
    with np.errstate(all="ignore"):
        corr = cov / (std[:, :, None] * std[:, None, :])
    either = undetermined[:, :, None] | undetermined[:, None, :]
    corr = np.where(either, np.nan, corr)
    diag = np.arange(n)
    corr[:, diag, diag] = np.where(undetermined, np.nan, 1.0)
    cov = np.where(either, np.inf, cov)
    width = np.where(np.isfinite(hi - lo), hi - lo, s_j)
    at_lo = np.isfinite(lo) & (np.abs(x - lo) <= AT_BOUND * width)
    at_hi = np.isfinite(hi) & (np.abs(x - hi) <= AT_BOUND * width)
    with np.errstate(invalid="ignore"):
        poorly = ~undetermined & np.isfinite(lo) & np.isfinite(hi) & (std > (hi - lo) / math.sqrt(12.0))

    statements, at_bound = [[] for _ in range(B)], [[] for _ in range(B)]
    kinds = [input_kind(path) for path in paths]
    for i in np.flatnonzero(null.any(axis=1) & ~bad):
        basis = _rref_basis(Vt[i].T[:, null[i]])
        for v in basis.T:
            involved = np.abs(v) >= INVOLVED * np.max(np.abs(v))
            fixed_by_prior = not any(undetermined[i][involved])
            priors = [paths[j] for j in np.flatnonzero(involved) if pw[i, j] > 0] if fixed_by_prior else []
            statements[i].append(describe_direction(paths, v, s_j[i], priors))
    for i in np.flatnonzero((at_lo | at_hi | poorly).any(axis=1) & ~bad):
        for j, (path, kind) in enumerate(zip(paths, kinds)):
            for side, b, at in (("lower", lo[i, j], at_lo[i, j]), ("upper", hi[i, j], at_hi[i, j])):
                if at:
                    at_bound[i].append(f"{path} is at its {side} bound {fmt(b, kind)}: the bound, not the evidence, "
                                       "sets it (its standard error ignores the bound)")
            if poorly[i, j]:
                statements[i].append(
                    f"{path} is poorly determined: its standard error {fmt(std[i, j], kind)} is wider than a uniform "
                    f"guess within its bounds ({fmt((hi[i, j] - lo[i, j]) / math.sqrt(12), kind)})")
    if bad.any():
        nan = np.nan
        cov[bad], std[bad], corr[bad], sv_full[bad] = nan, nan, nan, nan
        undetermined[bad], poorly[bad] = True, False
        for i in np.flatnonzero(bad):
            statements[i] = ["the model has no finite derivatives at the estimate: no uncertainty can be given"]
    return {"cov": cov, "std": std, "corr": corr, "singular": sv_full, "statements": statements,
            "undetermined": undetermined, "poorly": poorly, "at_bound": at_bound}
