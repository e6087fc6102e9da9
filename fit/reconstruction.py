"""``reconstruct`` and ``reconstruct_batch``: multi-start weighted least squares, one jitted call.

All starts of all cases go through one compiled, doubly vmapped solver (cases x starts; ``rows``); the best
start of each case is kept, and the Jacobian of the whitened residuals with respect to the physical unknowns is
evaluated there (in the same call) for the Laplace covariance (``uncertainty``). Monte Carlo refits perturbed
evidence the same way, through the same compiled program (``monte_carlo``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ks_jax.case import Case, CaseError, get_input
from ks_jax.case.scale import move_scene, origin_offset, scene_origin
from ks_jax.compilation import quick_jit
from ks_jax.limits import check_memory
from ks_jax.model.types import OK, status_text

from .monte_carlo import linearisation_notes, refit_perturbed
from .posterior import Posterior
from .posterior import sample as sample_posterior
from .posterior import sampler
from .problem import make_problem, output_units, parse_evidence, parse_unknowns, predict, to_z
from .rows import best_start, count_at_best, rows_per_call, run_rows, stack, stick_thresholds
from .solvers import SOLVERS
from .starts import first_starts
from .uncertainty import AT_BOUND, analyse, default_rtol


@dataclass
class FitResult:
    """One reconstruction (docs/fit.md). Values are SI (rad for angles, rad/s for rates);
    evidence-side values (``fitted``) are in the result's units (degrees for pdof, ...).

    status: the exchange's status at the estimate, or "invalid: ..." where nothing could be fitted
    (every start's residuals not finite; then every number is NaN).
    estimate, std: path -> value (std inf = not determined by the evidence); correlation:
    path -> path -> value (nan where undefined); fitted: evidence -> fitted value; residuals:
    evidence -> (fitted - measured) / sigma (angles wrapped); converged: the best start passed
    the solver's convergence test; unidentified: statements of what the evidence does not
    determine; at_bound: unknowns pinned at a bound; not_determined: the unknowns among them (not
    determined, or poorly: no usable standard error, and no Monte Carlo interval); monte_carlo: None or
    {"samples", "converged_fraction", "percentiles": {"5": {path: value}, ...}, "x": (samples, n_unknowns)
    array of every refit's estimate (SI, columns in the order of ``unknowns``), "converged": (samples,) bool};
    ``to_dict()`` keeps the first three.
    """

    case_name: str
    unknowns: list
    evidence: list
    estimate: dict
    std: dict
    correlation: dict
    fitted: dict
    residuals: dict
    converged: bool
    unidentified: list
    at_bound: list
    not_determined: list  # unknowns with no usable standard error: not determined or poorly determined
    cost: float
    status: str
    starts: int
    starts_converged: int
    starts_at_best: int
    iterations: int
    singular_values: list
    covariance: np.ndarray = field(repr=False)
    evidence_kinds: list = field(default_factory=list, repr=False)
    monte_carlo: dict | None = None
    notes: list = field(default_factory=list)
    posterior: Posterior | None = None

    @property
    def chi2(self) -> float:
        """Sum of squared whitened residuals (evidence and priors) at the estimate."""
        return 2.0 * self.cost

    def to_dict(self) -> dict:
        """JSON-ready (docs/fit.md, "JSON"): SI values, inf/nan -> null."""

        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None

        out = {
            "name": self.case_name,
            "estimate": {k: num(v) for k, v in self.estimate.items()},
            "std": {k: num(v) for k, v in self.std.items()},
            "correlation": {k: {k2: num(v2) for k2, v2 in row.items()} for k, row in self.correlation.items()},
            "residuals": {k: num(v) for k, v in self.residuals.items()},
            "fitted": {k: num(v) for k, v in self.fitted.items()},
            "converged": bool(self.converged),
            "unidentified": list(self.unidentified),
            "at_bound": list(self.at_bound),
            "chi2": num(self.chi2),
            "status": self.status,
            "measured": {k: num(e.value) for k, e in zip(self.residuals, self.evidence)},
            "sigma": {k: num(e.sigma) for k, e in zip(self.residuals, self.evidence)},
            "iterations": self.iterations,
            "starts": {"total": self.starts, "converged": self.starts_converged, "at_best": self.starts_at_best},
            "notes": list(self.notes),
        }
        if self.posterior is not None:
            out["posterior"] = self.posterior.to_dict()
        if self.monte_carlo is not None:
            mc = self.monte_carlo
            out["monte_carlo"] = {
                "samples": mc["samples"],
                "converged_fraction": mc["converged_fraction"],
                # an unknown the evidence does not determine has no interval: its refits spread over the bounds
                "percentiles": {p: {k: None if k in self.not_determined else num(v) for k, v in row.items()}
                                for p, row in mc["percentiles"].items()},
            }
        return out


def _keys(evidence):
    """Unique keys for evidence (a path named twice gets ' (2)')."""
    keys, seen = [], {}
    for e in evidence:
        seen[e.path] = seen.get(e.path, 0) + 1
        keys.append(e.path if seen[e.path] == 1 else f"{e.path} ({seen[e.path]})")
    return keys


def _prepare(case: Case, unknowns, evidence):
    if not isinstance(case, Case):
        raise TypeError(f"reconstruct needs a ks_jax Case, got {type(case).__name__}")
    if not case.valid:
        raise CaseError(case.error)
    if unknowns is None:
        unknowns = case.raw.get("unknowns")
    if evidence is None:
        evidence = case.raw.get("evidence")
    unknowns = parse_unknowns(case, unknowns)
    evidence = parse_evidence(case, evidence)
    problem = make_problem(case, unknowns, evidence)
    return unknowns, evidence, problem


def _arrays(case, unknowns, evidence, dtype):
    """The fit's arrays, SI, float64. In float32 with a scene more than 1 km from the origin, the scene is
    fitted about its CGs' midpoint (``ks_jax.case.scale.scene_origin``): ``inputs``, the bounds, priors and
    evidence values of x, y positions are moved by it, and ``x_offset``/``e_offset`` (what was subtracted
    from each unknown and each piece of evidence) move the results back. ``current`` (the case's values of
    the unknowns, for the starts) stays unmoved."""
    n = len(unknowns)
    origin = scene_origin(case.inputs, dtype=dtype)
    offsets = lambda paths: np.array([float(origin_offset(p, origin) or 0.0) for p in paths])  # noqa: E731
    x_offset = offsets([u.path for u in unknowns])
    e_offset = offsets([e.path for e in evidence])
    lo = np.array([u.lower for u in unknowns]) - x_offset
    hi = np.array([u.upper for u in unknowns]) - x_offset
    pm = np.array([u.prior[0] if u.prior else 0.0 for u in unknowns]) - x_offset
    pw = np.array([1.0 / u.prior[1] if u.prior else 0.0 for u in unknowns])
    values = np.array([e.value for e in evidence]) - e_offset
    sigmas = np.array([e.sigma for e in evidence])
    current = np.array([float(get_input(case.inputs, u.path)) for u in unknowns]) if n else np.zeros(0)
    inputs = case.inputs if origin is None else move_scene(case.inputs, origin, case.auto_point)
    return {"inputs": inputs, "values": values, "sigmas": sigmas, "lo": lo, "hi": hi, "pm": pm, "pw": pw,
            "current": current, "x_offset": x_offset, "e_offset": e_offset}


def _result(case, unknowns, evidence, problem, row, arrays, rtol) -> FitResult:
    paths = [u.path for u in unknowns]
    m = len(evidence)
    x = np.asarray(row["x"], np.float64) + arrays["x_offset"]  # in the case's coordinates (_arrays)
    info = analyse(unknowns, x, row["jacobian"], m, arrays["pw"], rtol)
    keys = _keys(evidence)
    cost_starts = row["cost_starts"]
    best_cost = float(row["cost"])
    at_best = count_at_best(cost_starts)
    notes = []
    res = row["residuals"][:m]
    status = status_text(row["status"])
    stalled = bool(row["stalled"])
    starts = len(cost_starts)
    if stalled:
        reached = int(np.sum(~np.asarray(row["stalled_starts"])))
        info["statements"] = [
            f"nothing is determined: the fit ended where the exchange is '{status}' (no impulse), and there no "
            f"unknown changes any evidence; {reached} of {starts} starts reached an exchange. This says nothing "
            "about the evidence: give starts or bounds where the vehicles collide (e.g. a speed's lower bound), "
            "or more starts (--starts)"]
        info["undetermined"][:] = True
        info["std"][:] = np.inf
    worst = [(k, r) for k, r in zip(keys, res) if abs(r) > 3]
    if worst and not stalled:
        notes.append("evidence not reproduced within 3 sigma: " + ", ".join(f"{k} ({r:+.1f} sigma)" for k, r in worst)
                     + ": " + _misfit_cause(at_best, starts))
    chi2, dof = 2.0 * best_cost, m + int(np.sum(arrays["pw"] > 0)) - int(np.sum(~info["undetermined"]))
    if not stalled and dof > 0 and chi2 > chi2_quantile(dof, CHI2_Z):
        notes.append(f"chi^2 = {chi2:.3g} for {dof} degree{'s' * (dof != 1)} of freedom: larger than the sigmas "
                     f"allow (by chance in under 1% of fits): " + _misfit_cause(at_best, starts))
    jac = np.asarray(row["jacobian"])[:m]
    for k, (path, is_out, _), jrow in zip(keys, problem.evidence, jac):
        if not is_out and np.all(jrow == 0):
            notes.append(f"evidence {k} is an input that no unknown changes: it only adds a constant to chi^2")
    if status != "ok":
        notes.append(f"the exchange at the estimate has status '{status}'")
    if "contact.friction" in paths and status == "ok":
        j = paths.index("contact.friction")
        mu, s, threshold = float(row["x"][j]), float(info["std"][j]), float(row.get("stick_threshold", np.nan))
        if not bool(row["sliding"]):
            _friction_bounded_below(info, j, float(row["stick_ratio"]), unknowns[j].prior)
        elif math.isfinite(s) and math.isfinite(threshold) and mu + NEAR_STICK * s >= threshold:
            _friction_bounded_below(info, j, threshold, unknowns[j].prior, sliding=(mu, s))
    corr = {p: {q: float(info["corr"][i, j]) for j, q in enumerate(paths)} for i, p in enumerate(paths)}
    return FitResult(
        case_name=case.name, unknowns=list(unknowns), evidence=list(evidence),
        estimate={p: float(v) for p, v in zip(paths, x)},
        std={p: float(v) for p, v in zip(paths, info["std"])},
        correlation=corr,
        fitted={k: float(v) for k, v in zip(keys, np.asarray(row["predicted"], np.float64) + arrays["e_offset"])},
        residuals={k: float(v) for k, v in zip(keys, res)},
        converged=bool(row["converged"]),
        unidentified=info["statements"], at_bound=info["at_bound"],
        not_determined=[p for p, a, b in zip(paths, info["undetermined"], info["poorly"]) if a or b],
        cost=best_cost, status=status, starts=len(cost_starts),
        starts_converged=int(np.sum(row["converged_starts"])), starts_at_best=at_best,
        iterations=int(row["iterations"]),
        singular_values=[float(s) for s in info["singular"]], covariance=info["cov"], notes=notes,
        evidence_kinds=[output_units(p, is_out) for p, is_out, _ in problem.evidence],
    )


_predict = quick_jit(predict, static_argnums=0)  # one row: quick to compile (``compilation.quick_jit``)


def _friction_bounded_below(info, j, least, prior=None, sliding=None):
    """A contact that sticks at the estimate: friction only has to exceed ``least`` (|J_t| / J_n); any
    value above gives the same exchange (to the smoothing), so the evidence sets no estimate of it.
    Marks unknown ``j`` not determined in ``info`` (``analyse``'s dict) and says so; with a prior
    (mean, sigma) on it, the prior alone fixes it: its standard error is the prior's sigma.
    ``sliding`` = (estimate, standard error): the contact slides at the estimate, but would stick from
    ``least`` on, within NEAR_STICK standard errors: above ``least`` the fit is as flat, so the
    standard error says nothing of how high friction can be; the evidence gives a lower limit only."""
    info["poorly"][j] = False
    info["corr"][j, :] = info["corr"][:, j] = np.nan
    info["cov"][j, :] = info["cov"][:, j] = np.inf
    if sliding is None:
        text = (f"contact.friction is bounded below only: the contact sticks at the estimate, which needs a friction "
                f"of at least {least:.3g}; any friction above that gives the same exchange, so the evidence sets no "
                "value")
    else:
        mu, s = sliding
        text = (f"contact.friction is bounded below only: the contact slides at the estimate ({mu:.3g} +/- {s:.2g} "
                f"by the linearisation), but from {least:.3g}, within {NEAR_STICK:g} standard errors, it would stick, "
                f"and every friction above that gives the same exchange; the evidence puts friction above about "
                f"{max(mu - NEAR_STICK * s, 0.0):.3g} and sets no value")
    if prior is None:
        info["std"][j] = np.inf
        info["undetermined"][j] = True
    else:
        info["std"][j] = prior[1]
        info["cov"][j, :] = info["cov"][:, j] = 0.0
        info["cov"][j, j] = prior[1] ** 2
        info["corr"][j, j] = 1.0
        text += ". Only the prior on contact.friction fixes it: its standard error is the prior's"
    info["statements"] = [s for s in info["statements"] if not s.startswith("contact.friction is ")] + [text]


NEAR_STICK = 2.0  # a sliding estimate within this many standard errors of sticking is bounded below only


CHI2_Z = 2.326  # the standard normal's 99% quantile: a chi^2 above its 99% quantile is a note


def chi2_quantile(dof: int, z: float) -> float:
    """The chi^2 distribution's quantile at the normal quantile z, by Wilson and Hilferty's cube-root
    approximation (within 1% of the exact 99% quantile from 1 degree of freedom up: 6.58 for 6.63)."""
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + z * math.sqrt(a)) ** 3


def _misfit_cause(at_best: int, starts: int) -> str:
    """Why a fit leaves evidence unexplained: bad evidence or sigmas, or a local minimum if few starts found it."""
    text = ("the evidence disagrees with itself or with the fixed inputs (the standard errors assume the sigmas "
            "are right, and are too small if they are not)")
    if at_best <= max(1, starts // 4):
        text += (f"; or this is a local minimum: only {at_best} of {starts} starts reached it, so run more starts "
                 "(--starts) before blaming the evidence")
    return text


def _not_fitted(case, unknowns, evidence, problem, arrays, x, smoothing, dtype, starts) -> FitResult:
    """The result of a case whose residuals (or their derivatives) are not finite at any start: its
    status says which evidence cannot be computed there, and why where that is known; every number is
    NaN (nothing was fitted, and nothing is blamed on the evidence's information)."""
    inputs = jax.tree_util.tree_map(lambda v: jnp.asarray(v, dtype), arrays["inputs"])
    pred, _ = _predict(problem, inputs, jnp.asarray(x, dtype), jnp.asarray(smoothing, dtype))
    pred = np.asarray(pred, np.float64)
    keys = _keys(evidence)
    bad = [k for k, v in zip(keys, pred) if not np.isfinite(v)]
    if bad:
        why = ("; EES is undefined where both crushes are 0 (the impulse centroid on or outside both boxes), "
               "so it cannot be evidence for such a contact" if any(k.split(" ")[0].endswith(".ees") for k in bad)
               else "")
        reason = f"invalid: {', '.join(bad)} cannot be computed (NaN) at any start{why}"
    else:
        reason = "invalid: the derivatives of the residuals are not finite at any start: nothing can be fitted"
    paths = [u.path for u in unknowns]
    nan = float("nan")
    return FitResult(
        case_name=case.name, unknowns=list(unknowns), evidence=list(evidence),
        estimate={p: nan for p in paths}, std={p: nan for p in paths},
        correlation={p: {q: nan for q in paths} for p in paths},
        fitted={k: nan for k in keys}, residuals={k: nan for k in keys},
        converged=False, unidentified=[], at_bound=[], not_determined=[], cost=float("inf"), status=reason,
        starts=starts,
        starts_converged=0, starts_at_best=0, iterations=0, singular_values=[],
        covariance=np.full((len(paths), len(paths)), nan), notes=[],
        evidence_kinds=[output_units(p, is_out) for p, is_out, _ in problem.evidence],
    )


def reconstruct(case: Case, unknowns=None, evidence=None, *, starts: int = 8, seed: int = 0, monte_carlo: int = 0,
                smoothing: float = 1e-3, solver: str = "lm", max_iter: int | None = None, rtol: float | None = None,
                progress: bool = False, chunk: int = 250, dtype=None, devices=None,
                max_starts: int | None = None, posterior: int = 0, chains: int = 4) -> FitResult:
    """Fit unknown inputs of ``case`` to ``evidence`` (docs/fit.md).

    case: a ks_jax Case with explicit or automatic contact. unknowns: a map path -> {"bounds",
    "start", "prior"} as in case files (unit strings, bare numbers SI except angles in degrees),
    or a list of ``Unknown`` (SI); default: the case file's ``unknowns``. evidence: a list of
    {"quantity", "value", "sigma"} as in case files or of ``Evidence`` (result units); default:
    the case file's ``evidence``. starts: multi-start count (the first at the given starts or
    the middle of the bounds, the others a Latin hypercube within the bounds (2% margins; normal
    draws about the first start where a bound is missing), seeded by ``seed``); where the best fit is not
    reached by two starts or more, or its chi^2 is above its distribution's 99% quantile, another ``starts``
    are drawn, and so on up to ``max_starts`` in all (default 8 x ``starts``; ``max_starts=starts``: one round).
    monte_carlo: number of refits with the evidence perturbed by its sigmas (0: none); their
    5/50/95 percentiles go to ``result.monte_carlo``. posterior: NUTS draws per chain from the posterior of
    the unknowns (0: none), ``chains`` chains started at the estimate, after as many adaptation steps
    (``fit.posterior``; the ``posterior`` extra): ``result.posterior``. smoothing: the engine's smooth friction
    cone tau (> 0 so that the loss is differentiable). solver: "lm" (default), "lbfgs" or
    "adam" (optax). rtol: relative singular-value threshold for ``unidentified`` (default 1e-6
    in float64, 1e-3 in float32). progress: show a progress bar for Monte Carlo (chunks of
    ``chunk`` samples) and for a posterior that runs more than 2 s. devices: where the starts and refits are solved (default: this process's devices,
    ``jax.local_devices()``; over several, the rows are split among them: docs/devices.md). Raises CaseError
    for a bad path, unit, bound or sigma.
    """
    return reconstruct_batch([case], None if unknowns is None else [unknowns],
                             None if evidence is None else [evidence], starts=starts, seed=seed,
                             monte_carlo=monte_carlo, smoothing=smoothing, solver=solver, max_iter=max_iter,
                             rtol=rtol, progress=progress, chunk=chunk, dtype=dtype, devices=devices,
                             max_starts=max_starts, posterior=posterior, chains=chains)[0]


MORE_STARTS = 8  # by default a fit takes up to this many rounds of ``starts`` starts (``_settled``)
AGREE = 2  # starts that must reach the best fit before a fit takes no more starts


def _settled(rows, problem, arrays) -> bool:
    """Whether a case's starts so far (``rows``: the solver's outputs, (starts, ...)) found a fit it can keep:
    the best cost reached by ``AGREE`` starts or more, with a chi^2 within its distribution's 99% quantile (the
    evidence's count plus the priors' less the unknowns' degrees of freedom, at least 1). A fit that no start can
    evaluate is settled: more starts would not help it."""
    cost = rows["cost"]
    if not np.isfinite(cost).any():
        return True
    dof = len(problem.evidence) + int(np.sum(arrays["pw"] > 0)) - len(problem.unknowns)
    chi2 = 2.0 * float(np.min(cost[np.isfinite(cost)]))
    return count_at_best(cost) >= AGREE and chi2 <= chi2_quantile(max(dof, 1), CHI2_Z)


SLIDE_SIDE = 1.0 - np.geomspace(0.02, 0.6, 8)  # the slide-side starts' friction, in parts of the friction needed to stick
OFF_BOUND = np.linspace(0.1, 0.9, 8)  # the off-bound starts of an unknown pinned at a bound, in parts of its range


def _other_side(rows, problem, arrays, count: int = 1):
    """``count`` starts (count, n) in x from a kept fit where the rounds of starts can stop short of the best
    fit, or None where there is no such place: the best fit has no exchange, or neither of these holds.

    - The contact sticks (friction an unknown without a prior, needed above its lower bound): the best fit with
      the friction at ``SLIDE_SIDE`` parts of what it needs. A contact that sticks has one cost for every
      friction above the one it needs (a flat plateau), so every start that reaches the plateau agrees on its
      cost; a sliding fit just below the edge, which the evidence may prefer, is reached only from that side.
    - Unknowns without a prior pinned at a bound: the best fit with each of them in turn at ``OFF_BOUND`` parts
      of its range. Starts that end against the same bound agree on its cost too, where a fit inside the
      bounds (a restitution that trades against the speeds) can be better."""
    if not np.isfinite(rows["cost"]).any():
        return None
    b = best_start(rows["cost"], rows["converged"])
    if rows["status"][b] != OK:
        return None
    best = np.asarray(rows["x"][b], np.float64)
    lo, hi = np.asarray(arrays["lo"], np.float64), np.asarray(arrays["hi"], np.float64)
    free = np.asarray(arrays["pw"]) <= 0
    x = np.repeat(best[None], count, axis=0)
    if "contact.friction" in problem.unknowns and not bool(rows["sliding"][b]):
        j = problem.unknowns.index("contact.friction")
        needed = float(abs(rows["stick_ratio"][b]))
        if free[j] and needed > lo[j]:
            x[:, j] = lo[j] + np.resize(SLIDE_SIDE, count) * (needed - lo[j])
            return x
    width = hi - lo
    pinned = [j for j in range(len(best)) if free[j] and np.isfinite(width[j]) and width[j] > 0
              and min(best[j] - lo[j], hi[j] - best[j]) <= AT_BOUND * width[j]]
    if not pinned:
        return None
    for k in range(count):
        j = pinned[k % len(pinned)]
        x[k, j] = lo[j] + OFF_BOUND[(k // len(pinned)) % len(OFF_BOUND)] * width[j]
    return x


MORE_BLOCKS = (8, 64)  # cases per call of a further round of starts: a few row counts, a program each


def _more_block(cases: int, todo: int, starts: int) -> int:
    """Rows per call of a further round of starts for ``todo`` of ``cases`` cases: the least of a few fixed
    counts (``MORE_BLOCKS`` cases, at most ``cases``) that holds them all, else the largest. A call's
    vmapped solver runs every row until its slowest converges, so a round of a few cases of a large batch is
    not padded to hundreds of rows; fixed counts keep the compiled programs to a few, and a batch of up to 8
    cases (a single fit among them) runs its further rounds in the program of its first."""
    sizes = sorted({min(c, cases) for c in MORE_BLOCKS})
    return next((c for c in sizes if c >= todo), sizes[-1]) * starts


def reconstruct_batch(cases, unknowns=None, evidence=None, *, starts: int = 8, seed: int = 0, monte_carlo: int = 0,
                      smoothing: float = 1e-3, solver: str = "lm", max_iter: int | None = None,
                      rtol: float | None = None, progress: bool = False, chunk: int = 250,
                      dtype=None, devices=None, max_starts: int | None = None, posterior: int = 0,
                      chains: int = 4) -> list[FitResult]:
    """Many reconstructions in one compiled, vmapped call (cases x starts).

    cases: list of Case (same contact mode). unknowns / evidence: one spec per case (lists of
    the same length as ``cases``), or None to read each case file's own. All cases must name
    the same unknown paths and the same evidence paths, in the same order (bounds, priors,
    values and sigmas may differ). Other arguments as ``reconstruct``; every start of every case is a row,
    and over several ``devices`` the rows are split among them.
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver = {solver!r}: known solvers are {', '.join(SOLVERS)}")
    if not 0.0 <= smoothing < 1.0:
        raise ValueError(f"smoothing = {smoothing}: must be in [0, 1) (use > 0 for a differentiable fit)")
    if starts < 1:
        raise ValueError(f"starts = {starts}: need at least one start")
    if posterior < 0 or chains < 1:
        raise ValueError(f"posterior = {posterior}, chains = {chains}: draws must be >= 0 and chains >= 1")
    if posterior:
        sampler()  # ImportError naming the extra, before any fit
    cases = list(cases)
    if not cases:
        return []
    dtype = dtype or jnp.result_type(float)
    rtol = default_rtol(dtype) if rtol is None else rtol
    max_iter = max_iter or {"lm": 50, "lbfgs": 200, "adam": 2000}[solver]
    specs_u = [None] * len(cases) if unknowns is None else list(unknowns)
    specs_e = [None] * len(cases) if evidence is None else list(evidence)
    if len(specs_u) != len(cases) or len(specs_e) != len(cases):
        raise ValueError("reconstruct_batch: give one unknowns spec and one evidence spec per case")
    prepared = [_prepare(c, u, e) for c, u, e in zip(cases, specs_u, specs_e)]
    problem = prepared[0][2]
    for c, (_, _, p) in zip(cases, prepared):
        if p != problem:
            raise CaseError(f"case '{c.name}': a batch needs the same unknowns, evidence paths and contact mode "
                            f"in every case (differs from case '{cases[0].name}')")
    # every start of every case is a row held at once (its inputs, Jacobian and state), as is every start of
    # the Monte Carlo refits drawn at once: refused up front where that cannot fit in memory
    m, n = len(problem.evidence), len(problem.unknowns)
    row_bytes = 8 * (3 * (m + n) * (n + 1) + 8 * n) + 2048
    check_memory(len(cases) * starts * row_bytes, f"{len(cases)} case(s) x {starts} starts",
                 "give fewer starts (--starts) or fit fewer cases at once")
    check_memory(int(monte_carlo) * starts * row_bytes, f"--monte-carlo {int(monte_carlo)} x {starts} starts",
                 "give fewer refits")
    arrays = [_arrays(c, u, e, dtype) for c, (u, e, _) in zip(cases, prepared)]
    rng = np.random.default_rng(seed)
    x0 = np.stack([first_starts(u, a, starts, rng) for (u, _, _), a in zip(prepared, arrays)])
    z0 = np.stack([to_z(x, a["lo"], a["hi"]) for x, a in zip(x0, arrays)])
    stacked = {k: np.stack([a[k] for a in arrays]) for k in ("values", "sigmas", "lo", "hi", "pm", "pw")}
    inputs = stack([a["inputs"] for a in arrays])
    # with refits, the fit, its further rounds of starts and the refits run in calls of one row count
    # (``ROWS_PER_CALL``): one compiled program
    block = rows_per_call(max(len(cases), int(monte_carlo)) * starts) if monte_carlo else None
    out = run_rows(problem, solver, max_iter, inputs, stacked["values"], stacked["sigmas"], stacked["lo"],
               stacked["hi"], stacked["pm"], stacked["pw"], z0, smoothing, dtype, starts, block, devices)
    out = [{k: v[i] for k, v in out.items()} for i in range(len(cases))]  # per case: (starts, ...)
    limit = MORE_STARTS * starts if max_starts is None else max(int(max_starts), starts)
    probed = set()
    while True:  # more starts where the best fit is not yet reached by several, or its chi^2 is improbable
        room = [i for i, o in enumerate(out) if len(o["cost"]) + starts <= limit]
        todo = [i for i in room if not _settled(out[i], problem, arrays[i])]
        if todo:
            z_more = np.stack([to_z(first_starts(prepared[i][0], arrays[i], starts + 1, rng)[1:], arrays[i]["lo"],
                                    arrays[i]["hi"]) for i in todo])
        else:  # settled: once per case, starts where the rounds can stop short (``_other_side``)
            sides = {i: _other_side(out[i], problem, arrays[i], starts) for i in room if i not in probed}
            todo = [i for i, x in sides.items() if x is not None]
            if not todo:
                break
            probed.update(todo)
            z_more = np.stack([to_z(sides[i], arrays[i]["lo"], arrays[i]["hi"]) for i in todo])
        more = run_rows(problem, solver, max_iter, stack([arrays[i]["inputs"] for i in todo]),
                        *(stacked[k][todo] for k in ("values", "sigmas", "lo", "hi", "pm", "pw")), z_more, smoothing,
                        dtype, starts, block or _more_block(len(cases), len(todo), starts), devices)
        for j, i in enumerate(todo):
            out[i] = {k: np.concatenate([v, more[k][j]]) for k, v in out[i].items()}
    best = [best_start(o["cost"], o["converged"]) for o in out]
    threshold = np.full(len(cases), np.nan)
    # the friction at which a sliding best fit would stick, for all those cases in one call
    sliding = [i for i, b in enumerate(best) if "contact.friction" in problem.unknowns and out[i]["status"][b] == OK
               and bool(out[i]["sliding"][b])]
    if sliding:
        threshold[sliding] = stick_thresholds(problem, stack([arrays[i]["inputs"] for i in sliding]),
                                              np.stack([out[i]["x"][best[i]] for i in sliding]), smoothing, dtype)
    results = []
    for i, (case, (u, e, _), a) in enumerate(zip(cases, prepared, arrays)):
        if not np.isfinite(out[i]["cost"]).any():  # no start could even be evaluated
            results.append(_not_fitted(case, u, e, problem, a, x0[i, 0], smoothing, dtype, len(out[i]["cost"])))
            continue
        row = {k: v[best[i]] for k, v in out[i].items()}
        row.update(cost_starts=out[i]["cost"], converged_starts=out[i]["converged"], stalled_starts=out[i]["stalled"],
                   stick_threshold=threshold[i])
        r = _result(case, u, e, problem, row, a, rtol)
        if posterior:
            r.posterior = sample_posterior(problem, a, row["z"], draws=int(posterior), chains=int(chains), seed=seed,
                                           smoothing=smoothing, dtype=dtype, devices=devices, offset=a["x_offset"],
                                           progress=progress)
        if monte_carlo:
            r.monte_carlo = refit_perturbed(problem, solver, max_iter, a, u, row["z"], starts, monte_carlo, rng,
                                         smoothing, dtype, progress, chunk, block, devices)
            r.notes += linearisation_notes(r)
        results.append(r)
    return results
