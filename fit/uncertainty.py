"""Uncertainty at the optimum: Laplace covariance, what the evidence does not determine, in words.

Everything here is NumPy on one case (small n x n matrices), after the jitted fit.

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


def scales(unknowns, x) -> np.ndarray:
    """Typical range s_j of each unknown (SI) for scaling the Jacobian's columns."""
    out = []
    for u, xj in zip(unknowns, x):
        if math.isfinite(u.lower) and math.isfinite(u.upper):
            out.append(u.upper - u.lower)
        elif u.prior is not None:
            out.append(u.prior[1])
        else:
            out.append(max(abs(float(xj)), 1.0))
    return np.asarray(out, dtype=np.float64)


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


def describe_direction(unknowns, v_scaled: np.ndarray, scale: np.ndarray, prior_paths: list[str]) -> str:
    """Words for a null direction v (in scaled units): which unknowns move together, by how much."""
    d = v_scaled * scale  # SI
    big = np.abs(v_scaled) >= INVOLVED * np.max(np.abs(v_scaled))
    idx = [j for j in range(len(unknowns)) if big[j]]  # in the user's order; the first is the reference
    names = [unknowns[j].path for j in idx]
    if len(idx) == 1:
        text = (f"{names[0]} is not determined by the evidence: changing it changes none of the evidence "
                "(to first order)")
    else:
        ref = idx[0]
        kind = input_kind(unknowns[ref].path)
        _, unit_si, step = DISPLAY.get(kind, ("", 1.0, 1.0))
        factor = step * unit_si / abs(d[ref])
        parts = []
        for j in idx:
            amount = d[j] * factor * np.sign(d[ref])
            verb = "raising" if amount > 0 else "lowering"
            parts.append(f"{verb} {unknowns[j].path} by {fmt(abs(amount), input_kind(unknowns[j].path), 3)}")
        listing = ", ".join(names[:-1]) + f" and {names[-1]}"
        text = (f"{listing} are not determined separately: {parts[0]} while " + ", ".join(parts[1:])
                + " changes none of the evidence (to first order); the evidence fixes only a combination of them")
    if prior_paths:
        text += f". Only the prior on {', '.join(prior_paths)} fixes this"
    return text


def analyse(unknowns, x, J, m: int, prior_weight, rtol: float):
    """Covariance and identifiability at the optimum.

    unknowns: list of Unknown (n); x (n,) SI; J (m + n, n): d(whitened residuals)/dx;
    m: number of evidence rows; prior_weight (n,): 1/prior sigma or 0; rtol: relative
    singular-value threshold. Returns dict with cov (n, n) (inf rows/cols for undetermined
    unknowns), std (n,), corr (n, n) (nan where undefined), singular (singular values of the
    scaled evidence Jacobian), statements (list of str), undetermined (n,) bool, poorly (n,) bool (a
    standard error wider than a uniform guess within the bounds), at_bound (list of str).
    """
    x = np.asarray(x, np.float64)
    J = np.asarray(J, np.float64)
    n = len(unknowns)
    pw = np.asarray(prior_weight, np.float64)
    s_j = scales(unknowns, x)
    Js = J[:m] * s_j
    statements = []
    if not np.all(np.isfinite(Js)):
        nan = np.full(n, np.nan)
        return {"cov": np.full((n, n), np.nan), "std": nan, "corr": np.full((n, n), np.nan), "singular": nan,
                "statements": ["the model has no finite derivatives at the estimate: no uncertainty can be given"],
                "undetermined": np.ones(n, bool), "poorly": np.zeros(n, bool), "at_bound": []}
    _, sv, Vt = np.linalg.svd(Js, full_matrices=True)
    sv_full = np.zeros(n)
    sv_full[: len(sv)] = sv
    smax = sv_full.max() if n else 0.0
    null = sv_full <= rtol * smax if smax > 0 else np.ones(n, bool)
    P = np.diag((pw * s_j) ** 2)
    H = Js.T @ Js + P
    lam, Q = np.linalg.eigh(H)
    cut = (rtol * smax) ** 2 if smax > 0 else 0.0
    lam_max = max(lam.max(), (pw * s_j).max() ** 2 if n else 0.0)
    cut = max(cut, rtol**2 * lam_max)
    keep = lam > cut
    N_total = Q[:, ~keep]
    undetermined = np.zeros(n, bool)
    if N_total.size:
        rows = np.abs(N_total)
        undetermined = np.max(rows / np.max(rows, axis=0, keepdims=True), axis=1) >= INVOLVED
    cov_s = (Q[:, keep] / lam[keep]) @ Q[:, keep].T
    cov = cov_s * np.outer(s_j, s_j)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    std[undetermined] = np.inf
    with np.errstate(all="ignore"):
        corr = cov / np.outer(std, std)
    corr[undetermined, :] = np.nan
    corr[:, undetermined] = np.nan
    np.fill_diagonal(corr, np.where(undetermined, np.nan, 1.0))
    cov[undetermined, :] = np.inf
    cov[:, undetermined] = np.inf

    if null.any():
        basis = _rref_basis(Vt.T[:, null])
        for v in basis.T:
            involved = np.abs(v) >= INVOLVED * np.max(np.abs(v))
            fixed_by_prior = not any(undetermined[involved])
            priors = [unknowns[j].path for j in np.flatnonzero(involved) if pw[j] > 0] if fixed_by_prior else []
            statements.append(describe_direction(unknowns, v, s_j, priors))
    at_bound = []
    poorly = np.zeros(n, bool)
    for j, u in enumerate(unknowns):
        kind = input_kind(u.path)
        width = u.upper - u.lower if math.isfinite(u.upper - u.lower) else s_j[j]
        for side, b in (("lower", u.lower), ("upper", u.upper)):
            if math.isfinite(b) and abs(x[j] - b) <= AT_BOUND * width:
                at_bound.append(f"{u.path} is at its {side} bound {fmt(b, kind)}: the bound, not the evidence, "
                                "sets it (its standard error ignores the bound)")
        if (not undetermined[j] and math.isfinite(u.lower) and math.isfinite(u.upper)
                and std[j] > (u.upper - u.lower) / math.sqrt(12.0)):
            poorly[j] = True
            statements.append(f"{u.path} is poorly determined: its standard error {fmt(std[j], kind)} is wider than "
                              f"a uniform guess within its bounds ({fmt((u.upper - u.lower) / math.sqrt(12), kind)})")
    return {"cov": cov, "std": std, "corr": corr, "singular": sv_full, "statements": statements,
            "undetermined": undetermined, "poorly": poorly, "at_bound": at_bound}
