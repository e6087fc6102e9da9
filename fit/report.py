"""Every sentence a fit says, and what a reconstructionist reads of it: values in the trade's units and SI
(``fmt``), what the evidence does not determine and why, the notes on a fit, and the report (``text_report``).
The rules that decide which sentence applies are elsewhere (``uncertainty``, ``reconstruction``,
``monte_carlo``); the words are made here alone."""

from __future__ import annotations

import math

from ks_jax import units as U
from ks_jax.case import input_kind

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


# What the evidence does not determine (``uncertainty.analyse_batch``)

def direction_statement(paths, d, involved, prior_paths) -> str:
    """Words for a direction ``d`` (SI, one component per unknown at ``paths``) that the evidence does not
    determine: the unknowns at ``involved`` (indices, the first the reference) move together, by how much; and
    which priors fix it."""
    names = [paths[j] for j in involved]
    if len(involved) == 1:
        text = (f"{names[0]} is not determined by the evidence: changing it changes none of the evidence "
                "(to first order)")
    else:
        ref = involved[0]
        _, unit_si, step = DISPLAY.get(input_kind(paths[ref]), ("", 1.0, 1.0))
        factor = step * unit_si / abs(d[ref])
        parts = []
        for j in involved:
            amount = d[j] * factor * math.copysign(1.0, d[ref])
            verb = "raising" if amount > 0 else "lowering"
            parts.append(f"{verb} {paths[j]} by {fmt(abs(amount), input_kind(paths[j]), 3)}")
        listing = ", ".join(names[:-1]) + f" and {names[-1]}"
        text = (f"{listing} are not determined separately: {parts[0]} while " + ", ".join(parts[1:])
                + " changes none of the evidence (to first order); the evidence fixes only a combination of them")
    if prior_paths:
        text += f". Only the prior on {', '.join(prior_paths)} fixes this"
    return text


def edge_statement(direction, needed) -> str:
    """A ``direction_statement`` of the slide side of a contact that sticks at the estimate
    (``uncertainty.on_the_edge``; ``needed``: the friction it needs to stick)."""
    return (f"{direction}, where the contact slides at a friction just below the {needed:.3g} it needs to stick, "
            "which fits the evidence as well as the estimate")


def at_bound_statement(path, side, bound) -> str:
    return (f"{path} is at its {side} bound {fmt(bound, input_kind(path))}: the bound, not the evidence, sets it "
            "(its standard error ignores the bound)")


def poorly_statement(path, std, guess) -> str:
    kind = input_kind(path)
    return (f"{path} is poorly determined: its standard error {fmt(std, kind)} is wider than a uniform guess within "
            f"its bounds ({fmt(guess, kind)})")


NO_DERIVATIVES = "the model has no finite derivatives at the estimate: no uncertainty can be given"
FRICTION_STATEMENT = "contact.friction is "  # how the friction rule's statement begins (one per fit)


def friction_statement(least, sliding=None, within=None, prior=False) -> str:
    """The friction of a contact that sticks at the estimate (``sliding`` None), or slides but would stick from
    ``least`` on within ``within`` standard errors (``sliding`` = (estimate, standard error)): bounded below only;
    with a ``prior``, the prior alone fixes it."""
    if sliding is None:
        text = (f"contact.friction is bounded below only: the contact sticks at the estimate, which needs a friction "
                f"of at least {least:.3g}; any friction above that gives the same exchange, so the evidence sets no "
                "value")
    else:
        mu, s = sliding
        text = (f"contact.friction is bounded below only: the contact slides at the estimate ({mu:.3g} +/- {s:.2g} "
                f"by the linearisation), but from {least:.3g}, within {within:g} standard errors, it would stick, "
                f"and every friction above that gives the same exchange; the evidence puts friction above about "
                f"{max(mu - within * s, 0.0):.3g} and sets no value")
    if prior:
        text += ". Only the prior on contact.friction fixes it: its standard error is the prior's"
    return text


def stalled_statement(status, ended, starts) -> str:
    """A fit that ended where nothing collides (``status``: the exchange's status text there; ``ended``: how many
    of the ``starts`` ended where the vehicles exchange an impulse). A start where they collide can end where
    they do not: the solver takes any step that lowers chi^2, and with evidence far from the start a miss can fit
    better than the start's collision."""
    return (f"nothing is determined: the fit ended where the exchange is '{status}' (no impulse), and there "
            f"no unknown changes any evidence; {ended} of {starts} starts ended at an exchange (a start where the "
            "vehicles collide can run off the exchange, where a miss fits the evidence better than the start "
            "does). This says nothing about the evidence: give more starts (--starts), or starts or bounds nearer "
            "the answer (e.g. a speed's lower bound)")


# Notes on a fit (``reconstruction``, ``monte_carlo``)

def misfit_cause(at_best: int, starts: int) -> str:
    """Why a fit leaves evidence unexplained: bad evidence or sigmas, or a local minimum if few starts found it."""
    text = ("the evidence disagrees with itself or with the fixed inputs (the standard errors assume the sigmas "
            "are right, and are too small if they are not)")
    if at_best <= max(1, starts // 4):
        text += (f"; or this is a local minimum: only {at_best} of {starts} starts reached it, so run more starts "
                 "(--starts) before blaming the evidence")
    return text


def misfit_note(worst, at_best, starts) -> str:
    """Evidence not reproduced within 3 sigma: ``worst`` [(key, residual in sigmas)]."""
    return ("evidence not reproduced within 3 sigma: " + ", ".join(f"{key} ({r:+.1f} sigma)" for key, r in worst)
            + ": " + misfit_cause(at_best, starts))


def improbable_note(chi2, dof, at_best, starts) -> str:
    return (f"chi^2 = {chi2:.3g} for {dof} degree{'s' * (dof != 1)} of freedom: larger than the sigmas "
            f"allow (by chance in under 1% of fits): " + misfit_cause(at_best, starts))


def unmoved_note(key) -> str:
    return f"evidence {key} is an input that no unknown changes: it only adds a constant to chi^2"


def status_note(status) -> str:
    return f"the exchange at the estimate has status '{status}'"


def not_fitted_status(bad) -> str:
    """The status of a case with nothing fitted: the evidence (keys ``bad``) that cannot be computed at any start,
    or, where every piece can, derivatives that are not finite."""
    if not bad:
        return "invalid: the derivatives of the residuals are not finite at any start: nothing can be fitted"
    why = ("; EES is undefined where both crushes are 0 (the impulse centroid on or outside both boxes), "
           "so it cannot be evidence for such a contact" if any(k.split(" ")[0].endswith(".ees") for k in bad)
           else "")
    return f"invalid: {', '.join(bad)} cannot be computed (NaN) at any start{why}"


def linearisation_note(path, estimate, std, p5, p50, p95) -> str:
    """Monte Carlo refits of ``path`` that contradict its standard error (``monte_carlo.linearisation_notes``)."""
    kind = input_kind(path)
    return (f"{path}: the Monte Carlo refits spread {fmt(p5, kind)} to {fmt(p95, kind)} (5-95%), median "
            f"{fmt(p50, kind)}, where the standard error gives {fmt(estimate - 1.645 * std, kind)} "
            f"to {fmt(estimate + 1.645 * std, kind)}: the results are not linear in it over its "
            f"uncertainty, or a bound cuts the refits off; read the Monte Carlo percentiles")


# The report

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
                      f"{_count(post.warmup, 'adaptation step')} toward acceptance {post.target_acceptance:g}; "
                      f"{post.divergences} divergent): mean +/- std; "
                      "2.5% / 50% / 97.5%; R-hat, ESS"]
        for u in result.unknowns:
            kind, s = input_kind(u.path), post.summary[u.path]
            if not math.isfinite(s["std"]):  # no chain moved: a point, not a distribution (the warning says so)
                lines.append(f"  {u.path:<{width}} {fmt(s['mean'], kind)}, where every chain stayed: no spread "
                             "measured (below)")
                continue
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
