"""Uncertainty at the optimum: Laplace covariance, and the rules of what the evidence does not determine (said in
words by ``report``).

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
from dataclasses import dataclass

import numpy as np

from .host import collector_paused
from .report import FRICTION_STATEMENT, NO_DERIVATIVES, at_bound_statement, direction_statement, edge_statement
from .report import friction_statement, poorly_statement

INVOLVED = 0.01
AT_BOUND = 1e-4

CHI2_Z = 2.326  # the standard normal's 99% quantile: a chi^2 above its 99% quantile is a note


def chi2_quantile(dof: int, z: float) -> float:
    """The chi^2 distribution's quantile at the normal quantile z, by Wilson and Hilferty's cube-root
    approximation (within 1% of the exact 99% quantile from 1 degree of freedom up: 6.58 for 6.63)."""
    a = 2.0 / (9.0 * np.asarray(dof, np.float64))
    return dof * (1.0 - a + z * np.sqrt(a)) ** 3


def default_rtol(dtype) -> float:
    return 1e-6 if np.finfo(dtype).eps < 1e-10 else 1e-3


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


@dataclass
class Analysis:
    """What the linearisation at the optimum says of B fits of the same n unknowns (``analyse_batch``): cov
    (B, n, n) (inf rows and columns for undetermined unknowns), std (B, n), corr (B, n, n) (NaN where undefined),
    singular (B, n) (singular values of the scaled evidence Jacobian), undetermined (B, n) (no standard error),
    poorly (B, n) (a standard error wider than a uniform guess within the bounds); and per fit the statements of
    what the evidence does not determine and of the unknowns at a bound (lists of str)."""

    cov: np.ndarray
    std: np.ndarray
    corr: np.ndarray
    singular: np.ndarray
    undetermined: np.ndarray
    poorly: np.ndarray
    statements: list
    at_bound: list
    directions: list

    def row(self, i: int) -> Analysis:
        """Fit ``i``'s analysis (arrays are views: editing them edits the batch's)."""
        return Analysis(self.cov[i], self.std[i], self.corr[i], self.singular[i], self.undetermined[i],
                        self.poorly[i], self.statements[i], self.at_bound[i], self.directions[i])


@collector_paused()
def analyse_batch(paths, x, J, m: int, lo, hi, prior_sigma, prior_weight, rtol: float) -> Analysis:
    """Covariance and identifiability at the optimum of B fits of the same unknowns, in NumPy's batched
    linear algebra (one decomposition call for all rows, not one per fit).

    paths: the n unknowns' input paths; x (B, n) SI; J (B, m + n, n): d(whitened residuals)/dx; m: number of
    evidence rows; lo, hi (B, n): the unknowns' bounds (SI, +-inf for none); prior_sigma (B, n) (NaN where
    none); prior_weight (B, n): 1/prior sigma or 0; rtol: relative singular-value threshold. Returns their
    ``Analysis``.
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

    statements, at_bound, directions = [[] for _ in range(B)], [[] for _ in range(B)], [[] for _ in range(B)]
    for i in np.flatnonzero(null.any(axis=1) & ~bad):
        basis = _rref_basis(Vt[i].T[:, null[i]])
        for v in basis.T:
            involved = np.abs(v) >= INVOLVED * np.max(np.abs(v))
            fixed_by_prior = not any(undetermined[i][involved])
            priors = [paths[j] for j in np.flatnonzero(involved) if pw[i, j] > 0] if fixed_by_prior else []
            text = direction_statement(paths, v * s_j[i], np.flatnonzero(involved).tolist(), priors)
            statements[i].append(text)
            directions[i].append((text, tuple(np.flatnonzero(involved).tolist())))
    for i in np.flatnonzero((at_lo | at_hi | poorly).any(axis=1) & ~bad):
        for j, path in enumerate(paths):
            for side, b, at in (("lower", lo[i, j], at_lo[i, j]), ("upper", hi[i, j], at_hi[i, j])):
                if at:
                    at_bound[i].append(at_bound_statement(path, side, b))
            if poorly[i, j]:
                statements[i].append(poorly_statement(path, std[i, j], (hi[i, j] - lo[i, j]) / math.sqrt(12)))
    if bad.any():
        nan = np.nan
        cov[bad], std[bad], corr[bad], sv_full[bad] = nan, nan, nan, nan
        undetermined[bad], poorly[bad] = True, False
        for i in np.flatnonzero(bad):
            statements[i] = [NO_DERIVATIVES]
    return Analysis(cov, std, corr, sv_full, undetermined, poorly, statements, at_bound, directions)


def on_the_edge(analysis: Analysis, rows, stick: Analysis, slide: Analysis, j: int, needed):
    """The rule for fits whose contact sticks at the estimate while the friction (unknown ``j``) is an unknown
    (``rows``: their indices in ``analysis``; ``stick``, ``slide``: their analyses with the Jacobian taken on
    either side of the edge of sticking, ``rows.edge_jacobians``; ``needed`` (K,): the friction each needs).

    A sticking contact gives one exchange for every friction above the one it needs, and so, at that friction,
    the contact that just slides gives the same exchange: the fit is as good there. Where the sliding exchange
    does not see a direction the sticking one sees (for the delta-Vs and yaw rates of two cars: the restitution
    and a centroid moved along the impulse's line trade against each other once the friction fixes the
    impulse's direction), the evidence fits as well along that direction, on the side where the contact keeps
    sliding, and so does not determine it. So: the stick side's analysis (free of the smoothing band's last
    bits, where the exchange at the estimate may half slide), and every unknown that the slide side leaves
    undetermined, but the friction (the friction rule's), is undetermined too, with the slide side's words.
    Edits ``analysis``."""
    for s_k, k in enumerate(np.asarray(rows).tolist()):
        a, st, sl = analysis.row(k), stick.row(s_k), slide.row(s_k)
        for name in ("cov", "std", "corr", "singular", "undetermined", "poorly"):
            getattr(a, name)[...] = getattr(st, name)
        newly = sl.undetermined & ~st.undetermined
        newly[j] = False
        added = [(text, inv) for text, inv in sl.directions if newly[list(inv)].any()]
        analysis.statements[k] = list(st.statements) + [edge_statement(text, float(needed[s_k])) for text, _ in added]
        analysis.directions[k] = list(st.directions) + added
        if newly.any():
            a.undetermined[newly] = True
            a.poorly[newly] = False
            a.std[newly] = np.inf
            a.cov[newly, :] = np.inf
            a.cov[:, newly] = np.inf
            a.corr[newly, :] = np.nan
            a.corr[:, newly] = np.nan


NEAR_STICK = 2.0  # a sliding estimate within this many standard errors of sticking is bounded below only


def friction_bounded_below(analysis: Analysis, j, x, ok, sliding, stick_ratio, threshold, priors):
    """The friction rule, for the fits of ``analysis`` whose unknown ``j`` is the contact's friction: where the
    contact sticks at the estimate (``ok`` and not ``sliding``, (K,)), friction only has to exceed the friction
    it needs (``stick_ratio`` = |J_t| / J_n); any value above gives the same exchange (to the smoothing), so the
    evidence sets no estimate of it. Where it slides at ``x`` (K, n) but would stick from ``threshold`` (K,) on,
    within ``NEAR_STICK`` standard errors, the fit is as flat above that, so the standard error says nothing of
    how high friction can be: the evidence gives a lower limit only. Such a friction is marked not determined and
    its statement replaces any other of it; with a prior ((mean, sigma) in ``priors``, else None), the prior alone
    fixes it: its standard error is the prior's sigma. Edits ``analysis``; call after chi^2's degrees of freedom
    are counted (the evidence's, as the fit has them)."""
    mu, sd = np.asarray(x[:, j], np.float64), analysis.std[:, j].copy()
    sticks = ok & ~sliding
    with np.errstate(invalid="ignore"):
        near = ok & ~sticks & np.isfinite(sd) & np.isfinite(threshold) & (mu + NEAR_STICK * sd >= threshold)
    for k in np.flatnonzero(sticks | near):
        a, prior = analysis.row(k), priors[k]
        if sticks[k]:
            text = friction_statement(float(stick_ratio[k]), prior=prior is not None)
        else:
            text = friction_statement(float(threshold[k]), (float(mu[k]), float(sd[k])), NEAR_STICK, prior is not None)
        a.poorly[j] = False
        a.corr[j, :] = a.corr[:, j] = np.nan
        a.cov[j, :] = a.cov[:, j] = np.inf
        if prior is None:
            a.std[j] = np.inf
            a.undetermined[j] = True
        else:
            a.std[j] = prior[1]
            a.cov[j, :] = a.cov[:, j] = 0.0
            a.cov[j, j] = prior[1] ** 2
            a.corr[j, j] = 1.0
        analysis.statements[k] = [s for s in a.statements if not s.startswith(FRICTION_STATEMENT)] + [text]
