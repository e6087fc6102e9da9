"""What a reconstructionist reads of a fit: estimates with standard errors in the trade's units and SI,
residuals in sigmas, what the evidence does not determine, convergence."""

from __future__ import annotations

import math

from ks_jax.case import input_kind

from .uncertainty import fmt


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
    if result.posterior is not None:
        post = result.posterior
        lines += ["", f"Posterior (NUTS, {_count(post.chains, 'chain')} x {_count(post.draws, 'draw')} after "
                      f"{_count(post.warmup, 'adaptation step')}; {post.divergences} divergent): mean +/- std; "
                      "2.5% / 50% / 97.5%; R-hat, ESS"]
        for u in result.unknowns:
            kind, s = input_kind(u.path), post.summary[u.path]
            lines.append(f"  {u.path:<{width}} {fmt(s['mean'], kind)} +/- {fmt(s['std'], kind)}; "
                         + " / ".join(fmt(s[q], kind) for q in ("q025", "q50", "q975"))
                         + f"; R-hat {_diagnostic(s['rhat'], '.3f')}, ESS {_diagnostic(s['ess'], '.0f')}")
        lines += [f"  warning: {w}" for w in post.warnings]
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


def _diagnostic(value: float, spec: str) -> str:
    """A posterior's R-hat or effective sample size, or "undefined" where it is not (R-hat of one chain; NaN
    inside, null in JSON): the warnings below the rows say why."""
    return format(value, spec) if math.isfinite(value) else "undefined"


def _count(k: int, noun: str) -> str:
    """'1 chain', '4 chains'."""
    return f"{k} {noun}{'s' * (k != 1)}"
