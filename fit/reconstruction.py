"""``reconstruct`` and ``reconstruct_batch``: multi-start weighted least squares, one jitted call.

All starts of all cases go through one compiled, doubly vmapped solver (cases x starts; ``rows``); the best
start of each case is kept, and the Jacobian of the whitened residuals with respect to the physical unknowns is
evaluated there (in the same call) for the Laplace covariance (``uncertainty``). Monte Carlo refits perturbed
evidence the same way, through the same compiled program (``monte_carlo``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ks_jax.backend import checked_devices, plan_for
from ks_jax.case import Case, CaseError
from ks_jax.compilation import quick_jit
from ks_jax.limits import check_memory, is_count, is_float_dtype, is_fraction
from ks_jax.model.types import OK, status_text

from .arrays import batch_arrays
from .host import collector_paused
from .monte_carlo import linearisation_notes, refit_perturbed
from .posterior import Posterior
from .posterior import sample as sample_posterior
from .posterior import TARGET_ACCEPTANCE, sampler
from .problem import Problem, predict, to_z
from .spec import PathChecks, check_batch, make_problem, output_units, parse_evidence, parse_unknowns
from .rounds import MORE_STARTS, Starts, more_block, other_side, settled
from .rows import EDGE, Row, count_at_best, edge_jacobians, fit_block, run_rows, several_minima, stick_thresholds
from .solvers import SOLVERS
from .starts import first_starts
from .report import improbable_note, misfit_note, not_fitted_status, stalled_statement, status_note, unmoved_note
from .uncertainty import CHI2_Z, analyse_batch, chi2_quantile, default_rtol, friction_bounded_below, on_the_edge


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
    starts: int | None  # these four None where the case was refused: nothing was tried
    starts_converged: int | None
    starts_at_best: int | None
    iterations: int | None
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


    @classmethod
    def refused(cls, name: str, error) -> FitResult:
        """The result of a case that could not be fitted because it breaks a rule (``error``, a CaseError or its
        message): status "invalid: <the message>", every table of paths empty, every count None, ``converged``
        false. Its ``to_dict`` has every key of a fitted case's (docs/fit.md, "JSON"), so that every case of a
        file or a batch has one shape, fitted or not."""
        message = str(error)
        return cls(case_name=name, unknowns=[], evidence=[], estimate={}, std={}, correlation={}, fitted={},
                   residuals={}, converged=False, unidentified=[], at_bound=[], not_determined=[], cost=math.nan,
                   status=message if message.startswith("invalid") else f"invalid: {message}", starts=None,
                   starts_converged=None, starts_at_best=None, iterations=None, singular_values=[],
                   covariance=np.zeros((0, 0)))


def _keys(paths):
    """Unique keys for evidence paths (a path named twice gets ' (2)')."""
    keys, seen = [], {}
    for path in paths:
        seen[path] = seen.get(path, 0) + 1
        keys.append(path if seen[path] == 1 else f"{path} ({seen[path]})")
    return keys


def _prepare(case: Case, unknowns, evidence, checks: PathChecks | None = None):
    """(unknowns, evidence, Problem) of one case, checked (CaseError); ``checks``: a batch's path checks."""
    if not isinstance(case, Case):
        raise TypeError(f"reconstruct needs a ks_jax Case, got {type(case).__name__}")
    if not case.valid:
        raise CaseError(case.error)
    if unknowns is None:
        unknowns = case.raw.get("unknowns")
    if evidence is None:
        evidence = case.raw.get("evidence")
    checks = checks or PathChecks()
    unknowns = parse_unknowns(case, unknowns, checks)
    evidence = parse_evidence(case, evidence, checks)
    problem = make_problem(case, unknowns, evidence, checks)
    return unknowns, evidence, problem


@functools.lru_cache(maxsize=64)
def _labels(problem: Problem):
    """A problem's evidence keys (``_keys``), their units (``output_units``) and which are inputs: the same for
    every case of a batch."""
    keys = tuple(_keys([path for path, _, _ in problem.evidence]))
    return keys, tuple(output_units(p, is_out) for p, is_out, _ in problem.evidence), \
        tuple(not is_out for _, is_out, _ in problem.evidence)


@collector_paused()
def _results(cases, prepared, problem, rows, at_best, stick_threshold, found, info, fitted,
             arrays) -> list[FitResult]:
    """The FitResults of the ``fitted`` cases of a batch (indices; the rows of ``info``, their analysis by
    ``analyse_batch``, in that order), from each case's best start (``rows``, ``RowFits`` (B, ...); ``at_best``
    (B,), how many starts reached it; ``stick_threshold`` (B,)) and its starts (``found``). The analysis is
    edited here where a fit stalled or its contact sticks; the numbers are converted for all the cases at once,
    and only the results' dicts and words are made case by case."""
    paths = list(problem.unknowns)
    keys, kinds, is_input = _labels(problem)
    m = len(keys)
    F = np.asarray(fitted)
    status, count, at_best = rows.status[F], found.count[F], at_best[F]
    stalled = rows.stalled[F].astype(bool)
    cost = rows.cost[F].astype(np.float64)
    texts = {code: status_text(code) for code in set(status.tolist())}
    for k in np.flatnonzero(stalled):
        i = F[k]
        ended = int(count[k]) - int(np.count_nonzero(found.table.stalled[i] & found.table.present[i]))
        info.statements[k] = [stalled_statement(texts[status[k]], ended, count[k])]
        info.undetermined[k] = True
        info.std[k] = np.inf
    chi2 = 2.0 * cost
    dof = m + np.count_nonzero(arrays.pw[F] > 0, axis=1) - np.count_nonzero(~info.undetermined, axis=1)
    improbable = ~stalled & (dof > 0) & (chi2 > chi2_quantile(np.maximum(dof, 1), CHI2_Z))
    res = rows.residuals[F, :m].astype(np.float64)
    misfit = ~stalled & (np.abs(res) > 3).any(axis=1)
    unmoved = ~np.any(rows.jacobian[F, :m] != 0, axis=2) & np.array(is_input, bool)  # (K, m)
    if "contact.friction" in paths:  # after chi^2's degrees of freedom
        j = paths.index("contact.friction")
        friction_bounded_below(info, j, rows.x[F], status == OK, rows.sliding[F].astype(bool),
                               rows.stick_ratio[F], stick_threshold[F],
                               [prepared[i][0][j].prior for i in F])
    x = (rows.x[F].astype(np.float64) + arrays.x_offset[F]).tolist()
    predicted = (rows.predicted[F].astype(np.float64) + arrays.e_offset[F]).tolist()
    std, corr, singular = info.std.tolist(), info.corr.tolist(), info.singular.tolist()
    not_determined = (info.undetermined | info.poorly).tolist()
    converged, iterations = rows.converged[F].tolist(), rows.iterations[F].tolist()
    converged_starts = np.count_nonzero(found.table.converged[F] & found.table.present[F], axis=1).tolist()
    res_list = res.tolist()
    out = []
    for k, i in enumerate(F.tolist()):
        unknowns, evidence, _ = prepared[i]
        starts, best = int(count[k]), int(at_best[k])
        notes = []
        if misfit[k]:
            notes.append(misfit_note([(key, r) for key, r in zip(keys, res_list[k]) if abs(r) > 3], best, starts))
        if improbable[k]:
            notes.append(improbable_note(chi2[k], int(dof[k]), best, starts))
        notes += [unmoved_note(key) for key, u in zip(keys, unmoved[k]) if u]
        text = texts[status[k]]
        if text != "ok":
            notes.append(status_note(text))
        out.append(FitResult(
            case_name=cases[i].name, unknowns=list(unknowns), evidence=list(evidence),
            estimate=dict(zip(paths, x[k])), std=dict(zip(paths, std[k])),
            correlation={p: dict(zip(paths, r)) for p, r in zip(paths, corr[k])},
            fitted=dict(zip(keys, predicted[k])), residuals=dict(zip(keys, res_list[k])),
            converged=bool(converged[k]), unidentified=info.statements[k], at_bound=info.at_bound[k],
            not_determined=[p for p, nd in zip(paths, not_determined[k]) if nd],
            cost=float(cost[k]), status=text, starts=starts, starts_converged=converged_starts[k],
            starts_at_best=best, iterations=int(iterations[k]), singular_values=singular[k],
            covariance=info.cov[k].copy(), notes=notes, evidence_kinds=list(kinds)))
    return out


_predict = quick_jit(predict, static_argnums=0)  # one row: quick to compile (``compilation.quick_jit``)


def _not_fitted(case, unknowns, evidence, problem, arrays, x, smoothing, dtype, starts) -> FitResult:
    """The result of a case whose residuals (or their derivatives) are not finite at any start: its
    status says which evidence cannot be computed there, and why where that is known; every number is
    NaN (nothing was fitted, and nothing is blamed on the evidence's information)."""
    inputs = jax.tree_util.tree_map(lambda v: jnp.asarray(v, dtype), arrays.inputs)
    pred, _ = _predict(problem, inputs, jnp.asarray(x, dtype), jnp.asarray(smoothing, dtype))
    pred = np.asarray(pred, np.float64)
    keys, kinds, _ = _labels(problem)
    reason = not_fitted_status([k for k, v in zip(keys, pred) if not np.isfinite(v)])
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
        covariance=np.full((len(paths), len(paths)), nan), notes=[], evidence_kinds=list(kinds),
    )


@collector_paused()
def _prepared_batch(cases, unknowns, evidence, starts, monte_carlo, errors):
    """Each case's (unknowns, evidence, Problem), checked, or the CaseError of a case that breaks a rule; and the
    batch's one Problem, that of its first case that breaks none: every case must have the same, and one that
    has another is refused too. ``errors``: "raise" the first case's error instead. The rows the fit and its
    refits hold at once are checked against the memory there is."""
    specs_u = [None] * len(cases) if unknowns is None else list(unknowns)
    specs_e = [None] * len(cases) if evidence is None else list(evidence)
    if len(specs_u) != len(cases) or len(specs_e) != len(cases):
        raise ValueError("reconstruct_batch: give one unknowns spec and one evidence spec per case")
    checks = PathChecks()
    prepared, problem, first = [], None, None
    for p, c, u, e in zip(check_batch(cases, specs_u, specs_e, checks), cases, specs_u, specs_e):
        try:
            p = p or _prepare(c, u, e, checks)
            if problem is not None and p[2] != problem:
                raise CaseError(f"case '{c.name}': a batch needs the same unknowns, evidence paths and contact mode "
                                f"in every case (differs from case '{first}')")
        except CaseError as err:
            if errors == "raise":
                raise
            p = err
        else:
            if problem is None:
                problem, first = p[2], c.name
        prepared.append(p)
    if problem is None:
        return prepared, None
    # every start of every case is a row held at once (its inputs, Jacobian and state), as is every start of
    # the Monte Carlo refits drawn at once: refused up front where that cannot fit in memory
    m, n = len(problem.evidence), len(problem.unknowns)
    row_bytes = 8 * (3 * (m + n) * (n + 1) + 8 * n) + 2048
    fitted = sum(not isinstance(p, CaseError) for p in prepared)
    check_memory(fitted * starts * row_bytes, f"{fitted} case(s) x {starts} starts",
                 "give fewer starts (--starts) or fit fewer cases at once")
    check_memory(int(monte_carlo) * starts * row_bytes, f"--monte-carlo {int(monte_carlo)} x {starts} starts",
                 "give fewer refits")
    return prepared, problem


def _check_arguments(errors, solver, smoothing, rtol, target_acceptance, dtype, **counts):
    """``reconstruct_batch``'s arguments, each against its rule (ValueError naming it), before any work; with a
    posterior, the sampler's extra (ImportError naming it)."""
    least = {"starts": 1, "chains": 1, "max_starts": 1, "max_iter": 1, "chunk": 1}
    if errors not in ("report", "raise"):
        raise ValueError(f"errors = {errors!r}: must be 'report' (a bad case's result says why) or 'raise'")
    if solver not in SOLVERS:
        raise ValueError(f"solver = {solver!r}: known solvers are {', '.join(SOLVERS)}")
    if not 0.0 <= smoothing < 1.0:
        raise ValueError(f"smoothing = {smoothing}: must be in [0, 1) (use > 0 for a differentiable fit)")
    for name, value in counts.items():
        if value is not None and not is_count(value, least.get(name, 0)):
            raise ValueError(f"{name} = {value!r}: must be a whole number >= {least.get(name, 0)}")
    if rtol is not None and not is_fraction(rtol):
        raise ValueError(f"rtol = {rtol!r}: the relative singular-value threshold must be in (0, 1)")
    if not is_fraction(target_acceptance):
        raise ValueError(f"target_acceptance = {target_acceptance!r}: the posterior's mean acceptance must be in "
                         "(0, 1) (Stan's default 0.8; 0.9 or 0.95 where transitions diverge)")
    if not (dtype is None or is_float_dtype(dtype)):
        raise ValueError(f"dtype = {dtype!r}: a fit computes in float32 or float64 (or None: JAX's default float)")
    if counts["posterior"]:
        sampler()  # ImportError naming the extra, before any fit


def reconstruct(case: Case, unknowns=None, evidence=None, *, starts: int = 8, seed: int = 0, monte_carlo: int = 0,
                smoothing: float = 1e-3, solver: str = "lm", max_iter: int | None = None, rtol: float | None = None,
                progress: bool = False, chunk: int = 250, dtype=None, devices=None,
                max_starts: int | None = None, posterior: int = 0, chains: int = 4, plan=None,
                target_acceptance: float = TARGET_ACCEPTANCE) -> FitResult:
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
    (``fit.posterior``; the ``posterior`` extra): ``result.posterior``; their warmup tunes each chain's step size
    toward a mean acceptance of ``target_acceptance`` (in (0, 1); nearer 1, smaller steps and fewer divergent
    transitions where the posterior bends sharply, as at a bound, for more gradients per draw). smoothing: the
    engine's smooth friction cone tau (> 0 so that the loss is differentiable). solver: "lm" (default), "lbfgs" or
    "adam" (optax). rtol: relative singular-value threshold for ``unidentified`` (default 1e-6
    in float64, 1e-3 in float32). progress: show a progress bar for Monte Carlo (chunks of
    ``chunk`` samples) and for a posterior that runs more than 2 s. devices: where the starts and refits are solved
    (default: this process's devices, ``jax.local_devices()``; over several, the rows are split among them:
    docs/devices.md). plan: how the rows are computed, a ``ks_jax.backend.Plan`` or its path ("cpu",
    "accelerator"); default, the path of ``devices``. dtype: float32 or float64, what the fit computes in (default
    JAX's default float). Raises CaseError for a bad path, unit, bound or sigma.
    """
    return reconstruct_batch([case], None if unknowns is None else [unknowns],
                             None if evidence is None else [evidence], starts=starts, seed=seed,
                             monte_carlo=monte_carlo, smoothing=smoothing, solver=solver, max_iter=max_iter,
                             rtol=rtol, progress=progress, chunk=chunk, dtype=dtype, devices=devices,
                             max_starts=max_starts, posterior=posterior, chains=chains, plan=plan,
                             target_acceptance=target_acceptance, errors="raise")[0]


def reconstruct_batch(cases, unknowns=None, evidence=None, *, starts: int = 8, seed: int = 0, monte_carlo: int = 0,
                      smoothing: float = 1e-3, solver: str = "lm", max_iter: int | None = None,
                      rtol: float | None = None, progress: bool = False, chunk: int = 250,
                      dtype=None, devices=None, max_starts: int | None = None, posterior: int = 0,
                      chains: int = 4, plan=None, target_acceptance: float = TARGET_ACCEPTANCE,
                      errors: str = "report") -> list[FitResult]:
    """Many reconstructions in one compiled, vmapped call (cases x starts).

    cases: list of Case (same contact mode). unknowns / evidence: one spec per case (lists of
    the same length as ``cases``), or None to read each case file's own. All cases must name
    the same unknown paths and the same evidence paths, in the same order (bounds, priors,
    values and sigmas may differ). Other arguments as ``reconstruct``; every start of every case is a row,
    and over several ``devices`` the rows are split among them. errors: "report" (default), a case that breaks a
    rule (a bad path, unit, bound or sigma, an invalid case, or paths other than the batch's first good case's)
    is not fitted and its result says why (``FitResult.refused``: status "invalid: ..."), and the others are
    fitted; "raise", its CaseError is raised before any fit. An argument that is not a Case is a TypeError.
    """
    _check_arguments(errors, solver, smoothing, rtol, target_acceptance, dtype, starts=starts, monte_carlo=monte_carlo,
                     posterior=posterior, chains=chains, max_starts=max_starts, max_iter=max_iter, chunk=chunk)
    devices = checked_devices(devices, "reconstruct_batch")
    cases = list(cases)
    if not cases:
        return []
    dtype = dtype or jnp.result_type(float)
    rtol = default_rtol(dtype) if rtol is None else rtol
    max_iter = max_iter or {"lm": 50, "lbfgs": 200, "adam": 2000}[solver]
    prepared, problem = _prepared_batch(cases, unknowns, evidence, starts, monte_carlo, errors)
    out = [FitResult.refused(c.name, p) if isinstance(p, CaseError) else None for c, p in zip(cases, prepared)]
    fitting = [i for i, r in enumerate(out) if r is None]
    if not fitting:
        return out
    cases, prepared = [cases[i] for i in fitting], [prepared[i] for i in fitting]  # from here on, those fitted
    problem = dataclasses.replace(problem, plan=plan_for(plan, devices))
    arrays, case_inputs = batch_arrays(cases, prepared, dtype)
    rng = np.random.default_rng(seed)
    x0 = first_starts(problem.unknowns, arrays, starts, rng)

    def per_case(a):  # what the solver's rows take of each case, after its inputs
        return a.values, a.sigmas, a.lo, a.hi, a.pm, a.pw

    # with refits, and on an accelerator's path, the fit, its further rounds of starts and the refits run in calls of
    # one row count (``rows.fit_block``): one compiled program
    block = fit_block(len(cases) * starts, int(monte_carlo), problem.plan, len(devices))
    first = run_rows(problem, solver, max_iter, arrays.inputs, *per_case(arrays),
                     to_z(x0, arrays.lo[:, None], arrays.hi[:, None]), smoothing, dtype, starts, block, devices)
    found = Starts(first)
    limit = MORE_STARTS * starts if max_starts is None else max(int(max_starts), starts)
    dof = len(problem.evidence) + np.sum(arrays.pw > 0, axis=1) - len(problem.unknowns)
    probed = np.zeros(len(cases), bool)
    while True:  # more starts where the best fit is not yet reached by several, or its chi^2 is improbable
        room = found.count + starts <= limit
        todo = np.flatnonzero(room & ~settled(found.table.cost, dof))
        if todo.size:
            x_more = first_starts(problem.unknowns, arrays.take(todo), starts + 1, rng)[:, 1:]
        else:  # settled: once per case, starts where the rounds can stop short (``rounds.other_side``)
            ask = np.flatnonzero(room & ~probed & np.isfinite(found.table.cost).any(axis=1))
            best = found.best(ask, ("x", "status", "sliding", "stick_ratio"))
            sides, x_more = other_side(best, problem, arrays.lo[ask], arrays.hi[ask], arrays.pw[ask], starts)
            todo = ask[sides]
            if not todo.size:
                break
            probed[todo] = True
        z_more = to_z(x_more, arrays.lo[todo, None], arrays.hi[todo, None])
        some = arrays.take(todo)
        found.add(todo, run_rows(problem, solver, max_iter, some.inputs, *per_case(some), z_more, smoothing, dtype,
                                 starts, block or more_block(len(cases), todo.size, starts), devices))
    everyone = np.arange(len(cases))
    rows = found.best(everyone)
    at_best = count_at_best(found.table.cost)
    fitted = np.flatnonzero(np.isfinite(found.table.cost).any(axis=1))
    # the friction at which a sliding best fit would stick, for all those cases in one call
    stick_threshold = np.full(len(cases), np.nan)
    if "contact.friction" in problem.unknowns:
        sliding = fitted[(rows.status[fitted] == OK) & rows.sliding[fitted].astype(bool)]
        if sliding.size:
            stick_threshold[sliding] = stick_thresholds(problem, arrays.take(sliding).inputs, rows.x[sliding],
                                                        smoothing, dtype)
    kept = arrays.take(fitted)
    info = analyse_batch(problem.unknowns, rows.x[fitted] + kept.x_offset, rows.jacobian[fitted],
                         len(problem.evidence), kept.lower, kept.upper, kept.prior_sigma, kept.pw,
                         rtol)
    if "contact.friction" in problem.unknowns:  # fits that stick, on the edge of sliding
        j = problem.unknowns.index("contact.friction")
        needed = np.abs(rows.stick_ratio[fitted].astype(np.float64))
        with np.errstate(invalid="ignore"):
            edge = np.flatnonzero((rows.status[fitted] == OK) & ~rows.sliding[fitted].astype(bool)
                                  & (needed * (1.0 - EDGE) > kept.lower[:, j]))
        if edge.size:
            on, x = kept.take(edge), rows.x[fitted][edge]
            sides = edge_jacobians(problem, Row(on.inputs, *per_case(on)), x, needed[edge], smoothing, dtype)
            stick, slide = (analyse_batch(problem.unknowns, x + on.x_offset, J, len(problem.evidence), on.lower,
                                          on.upper, on.prior_sigma, on.pw, rtol) for J in sides)
            on_the_edge(info, edge, stick, slide, j, needed[edge])

    def arrays_of(i):
        return arrays.row(i, case_inputs[i])

    results = [None] * len(cases)
    for i, r in zip(fitted.tolist(), _results(cases, prepared, problem, rows, at_best, stick_threshold, found, info,
                                              fitted, arrays)):
        results[i] = r
    for i, (case, (u, e, _)) in enumerate(zip(cases, prepared)):
        if results[i] is None:  # no start could even be evaluated
            results[i] = _not_fitted(case, u, e, problem, arrays_of(i), x0[i, 0], smoothing, dtype, int(found.count[i]))
            continue
        r, z = results[i], rows.z[i]
        if posterior:
            r.posterior = sample_posterior(problem, arrays_of(i), z, draws=int(posterior), chains=int(chains),
                                           seed=seed, smoothing=smoothing, dtype=dtype, devices=devices,
                                           offset=arrays.x_offset[i], progress=progress,
                                           target_acceptance=target_acceptance)
        if monte_carlo:
            everywhere = several_minima(found.table.cost[i], found.table.converged[i])
            r.monte_carlo = refit_perturbed(problem, solver, max_iter, arrays_of(i), u, z, starts, monte_carlo, rng,
                                            smoothing, dtype, progress, chunk, block, devices, everywhere)
            r.notes += linearisation_notes(r)
    for i, r in zip(fitting, results):
        out[i] = r
    return out
