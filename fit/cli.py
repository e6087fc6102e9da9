"""`ks-jax fit FILE`: reconstruct the case's ``unknowns`` from its ``evidence`` (MODEL.md section 6).

Text report: estimates +/- standard error in the reconstructionist's units (mph, deg, ft) and
SI, residuals in sigmas, what the evidence does not determine, convergence. ``--json``: the
result of ``FitResult.to_dict`` (SI values, null for "not determined"); with several cases in
the file, ``{"cases": [...]}``. Monte Carlo shows a progress bar on stderr (tqdm if installed,
else lines).
"""

from __future__ import annotations

import json
import math
import sys

from ks_jax.case import CaseError, input_kind, load_cases
from ks_jax.cli import seed_option, smoothing_option

from .uncertainty import fmt


def add_arguments(parser) -> None:
    parser.add_argument("file", help="case file (JSON or TOML) with 'unknowns' and 'evidence'")
    parser.add_argument("--json", action="store_true", help="print the result as JSON (SI units)")
    parser.add_argument("--starts", type=int, default=8, help="multi-start count (default 8)")
    parser.add_argument("--monte-carlo", type=int, default=0, metavar="N",
                        help="refit N copies of the evidence perturbed by its sigmas; report 5/50/95 percentiles")
    parser.add_argument("--seed", type=seed_option, default=0, help="random seed for the starts and Monte Carlo")
    parser.add_argument("--smoothing", type=smoothing_option, default=1e-3,
                        help="smooth friction cone tau (> 0 keeps the fit differentiable; default 1e-3)")
    parser.add_argument("--solver", choices=("lm", "lbfgs", "adam"), default="lm",
                        help="lm: Levenberg-Marquardt (default); lbfgs, adam: optax")


def text_report(result) -> str:
    """What a reconstructionist reads: estimates, residuals, what is not determined."""
    if result.status.startswith("invalid"):
        return f"Reconstruction: {result.case_name}\n  not fitted: {result.status}"
    lines = [f"Reconstruction: {result.case_name}", ""]
    width = max(len(u.path) for u in result.unknowns) + 2
    lines.append("Estimates (+/- one standard error, Laplace):")
    for u in result.unknowns:
        kind = input_kind(u.path)
        x, s = result.estimate[u.path], result.std[u.path]
        std = "not determined by the evidence" if not math.isfinite(s) else f"+/- {fmt(s, kind)}"
        lines.append(f"  {u.path:<{width}} {fmt(x, kind, si=True):<34} {std}")
    if result.monte_carlo:
        mc = result.monte_carlo
        lines += ["", f"Monte Carlo ({mc['samples']} refits of perturbed evidence, "
                      f"{100 * mc['converged_fraction']:.0f}% converged): 5% / 50% / 95%"]
        for u in result.unknowns:
            kind = input_kind(u.path)
            if u.path in result.not_determined:  # the refits spread over the bounds: not an interval
                lines.append(f"  {u.path:<{width}} no interval: not determined by the evidence (below)")
                continue
            p = [mc["percentiles"][q][u.path] for q in ("5", "50", "95")]
            lines.append(f"  {u.path:<{width}} " + " / ".join(fmt(v, kind) for v in p))
    lines += ["", "Evidence (fitted vs measured, residual in sigmas):"]
    ew = max(len(k) for k in result.residuals) + 2
    for e, kind, (key, res) in zip(result.evidence, result.evidence_kinds, result.residuals.items()):
        lines.append(f"  {key:<{ew}} fitted {fmt(result.fitted[key], kind):<16} measured "
                     f"{fmt(e.value, kind):<16} +/- {fmt(e.sigma, kind):<12} {res:+.2f} sigma")
    lines.append(f"  chi^2 = {result.chi2:.3g} for {len(result.evidence)} evidence, {len(result.unknowns)} unknowns")
    lines += ["", "Not determined by the evidence:"]
    lines += [f"  - {s}" for s in result.unidentified] or ["  (nothing: every unknown is determined)"]
    if result.at_bound:
        lines += ["", "At a bound:"] + [f"  - {s}" for s in result.at_bound]
    if result.notes:
        lines += ["", "Notes:"] + [f"  - {s}" for s in result.notes]
    lines += ["", f"Converged: {'yes' if result.converged else 'NO'} ({result.iterations} iterations; "
                  f"{result.starts_converged} of {result.starts} starts converged, {result.starts_at_best} reached "
                  f"the best fit); exchange status at the estimate: {result.status}"]
    return "\n".join(lines)


def run(args) -> int:
    from .reconstruction import reconstruct

    cases = load_cases(args.file)
    if args.starts < 1:
        raise CaseError(f"--starts {args.starts}: need at least one start")
    if args.monte_carlo < 0:
        raise CaseError(f"--monte-carlo {args.monte_carlo}: must be >= 0")
    results, failed = [], {}
    for k, case in enumerate(cases):
        try:
            if not case.valid:
                raise CaseError(case.error)
            for key in ("unknowns", "evidence"):
                if key not in case.raw:
                    raise CaseError(f"case '{case.name}': {key}: missing field (ks-jax fit needs 'unknowns' and "
                                    "'evidence', MODEL.md section 6)")
            results.append(reconstruct(case, starts=args.starts, seed=args.seed, monte_carlo=args.monte_carlo,
                                       smoothing=args.smoothing, solver=args.solver, progress=args.monte_carlo > 0))
        except CaseError as err:  # in a file of several cases: reported, and the others are fitted
            if len(cases) == 1:
                raise
            failed[k] = str(err) if str(err).startswith("invalid") else f"invalid: {err}"
            results.append(None)
    if args.json:
        dicts = [{"name": c.name, "status": failed[k]} if r is None else r.to_dict()
                 for k, (c, r) in enumerate(zip(cases, results))]
        print(json.dumps(dicts[0] if len(dicts) == 1 else {"cases": dicts}, indent=1))
    else:
        print("\n\n".join(f"Reconstruction: {c.name}\n  not fitted: {failed[k]}" if r is None else text_report(r)
                           for k, (c, r) in enumerate(zip(cases, results))))
    failed.update((k, r.status) for k, r in enumerate(results) if r is not None and r.status.startswith("invalid"))
    for k, message in sorted(failed.items()):
        print(f"ks-jax: case '{cases[k].name}' not fitted: {message}", file=sys.stderr)
    return 1 if failed else 0
