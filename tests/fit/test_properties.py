"""Properties of the fit that hold whatever the numbers (hypothesis), and how often it finds the truth.

Each problem: a case drawn from a template, a truth drawn inside the bounds for 1 to 6 unknowns of every kind
the fit takes (speeds, restitution, friction, the impulse centroid, the normal, a yaw rate, and in a case with a
road, the road's friction and a wheel's braking), bounds on both sides, on one or on none, an optional start, an
optional Gaussian prior off the truth, and noise-free evidence of every kind (delta-V, PDOF, crush, speeds and
yaw rates after, rest positions and rest yaw) computed from the truth by ``ks_jax.solve``, with drawn sigmas.

Whatever is drawn, a fit must end without an exception, with a finite chi^2, a text report in plain words and
a JSON dict without NaN, its estimates within their bounds, and (with a posterior) a summary for every unknown.
And over a fixed, seeded batch of 200 such problems, at least 99% must reach the chi^2 of the truth (0 for the
evidence, plus what the priors' offsets put there): the independent reference is the truth itself.

Compiling is most of a fit's cost, and one program serves every fit of one set of paths and one row count: so
the problems come from three fixed sets of paths (``PATH_SETS``: six unknowns of a collision, one unknown, three
unknowns of a motion to rest), always fitted in batches of ``BATCH`` cases, and evidence is computed in batches
of as many: each set compiles one solver, one forward solve, and (for one set) one sampler.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from dataclasses import dataclass

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fit
from fit.report import text_report
from fit.synthetic import oblique_case
from ks_jax.case import case_from_dict, get_input, get_output, set_input
from ks_jax.solve import solve
from samples import CASES

pytestmark = pytest.mark.slow  # samplers and batches of fits: each compiles programs of its own

BATCH = 8  # cases per fit call: one compiled program per set of paths (its rounds run in calls of as many)
SMOOTHING = 1e-3  # the fit's default, which the evidence is computed with too
REACH = 1e-6  # a fit reaches the truth's chi^2 when its own is at most this much (absolute, and relative) above it


@dataclass(frozen=True)
class Kind:
    """An unknown: its input ``path``; the truth drawn in [lo, hi] (added to the template's value where
    ``relative``); its bounds ``span`` (the distance from the truth to a bound is 0.2 to 2 spans), clipped to the
    input's own ``limits``; which bounds may be left out (``open_lower``, ``open_upper``)."""

    path: str
    lo: float
    hi: float
    span: float
    limits: tuple = (-math.inf, math.inf)
    relative: bool = False
    open_lower: bool = True
    open_upper: bool = True


@dataclass(frozen=True)
class PathSet:
    name: str
    template: object  # rng -> case dict
    unknowns: tuple  # of Kind
    evidence: tuple  # of (path, sigma in the result's units)
    starts: int = 8


def _collision(rng) -> dict:
    return oblique_case(rng)


def _motion(rng) -> dict:
    """A low-speed T-bone that spins out to rest within a couple of seconds, integrated in steps of 50 ms so that
    each fit's motion takes a few dozen steps (the sedan's front left wheel braked, the pickup's locked)."""
    d = json.loads((CASES / "fit_rest_positions.json").read_text())
    for key in ("unknowns", "evidence"):
        d.pop(key)
    d["vehicles"][0]["speed"] = f"{rng.uniform(8, 12):.3f} mph"
    d["vehicles"][1]["speed"] = "15 mph"
    d["road"] = {"friction": 0.8, "time_step": 0.05, "time_limit": 5}
    return d


PATH_SETS = {
    "collision": PathSet(
        "collision", _collision,
        (Kind("vehicles[0].speed", 8.0, 20.0, 10.0, (0.0, math.inf)),
         Kind("vehicles[1].speed", 8.0, 20.0, 10.0, (0.0, math.inf), open_lower=False),
         Kind("contact.restitution", 0.05, 0.3, 0.2, (0.0, 0.8), open_lower=False, open_upper=False),
         Kind("contact.friction", 0.1, 0.35, 0.3, (0.0, 1.5), open_lower=False),
         Kind("contact.point[0]", -0.2, 0.2, 0.8, relative=True),
         Kind("contact.normal", -0.1, 0.1, 0.3, relative=True)),
        (("vehicles[0].delta_v_body[0]", 0.2), ("vehicles[0].delta_v_body[1]", 0.2),
         ("vehicles[1].delta_v_body[0]", 0.2), ("vehicles[1].delta_v_body[1]", 0.2),
         ("vehicles[0].pdof", 3.0), ("vehicles[1].pdof", 3.0), ("vehicles[0].crush", 0.03),
         ("vehicles[1].crush", 0.03), ("vehicles[0].speed_after", 0.2), ("vehicles[1].speed_after", 0.2),
         ("vehicles[0].yaw_rate_after", 0.02), ("vehicles[1].yaw_rate_after", 0.02))),
    "one": PathSet(
        "one", _collision,
        (Kind("vehicles[1].yaw_rate", -0.2, 0.2, 0.5),),
        (("vehicles[1].yaw_rate_after", 0.02), ("vehicles[0].delta_v_magnitude", 0.2))),
    "motion": PathSet(
        "motion", _motion,
        (Kind("vehicles[1].speed", 5.5, 8.0, 3.0, (2.0, math.inf), open_lower=False),
         Kind("road.friction", 0.6, 1.0, 0.3, (0.2, 1.5), open_lower=False, open_upper=False),
         Kind("vehicles[0].brake[0]", 0.2, 0.8, 0.5, (0.0, 1.0), open_lower=False, open_upper=False)),
        (("vehicles[0].rest_position[0]", 0.3), ("vehicles[0].rest_position[1]", 0.3),
         ("vehicles[1].rest_position[0]", 0.3), ("vehicles[1].rest_position[1]", 0.3),
         ("vehicles[1].rest_yaw", 3.0), ("vehicles[0].crush", 0.03)),
        starts=4),
}


@dataclass(frozen=True)
class Draw:
    """The numbers of one unknown of one problem, each in [0, 1] or a flag: where the truth lies in its range
    (``t``), how far each bound is (``below``, ``above``: 0.2 to 2 spans), whether it is left out, where the start
    is (None: none given), and the prior (None, or its mean's offset from the truth in its sigmas, in [-2, 2], and
    its sigma in spans, 0.05 to 2)."""

    t: float
    below: float
    above: float
    no_lower: bool
    no_upper: bool
    start: float | None
    prior: tuple | None


@dataclass(frozen=True)
class Drawn:
    case_seed: int
    sigma_scale: float  # every sigma times this (0.3 to 3)
    draws: tuple


def _unknown(kind: Kind, base: float, d: Draw):
    """(fit.Unknown, truth, the truth's prior chi^2) of one drawn unknown."""
    lo_limit, hi_limit = kind.limits
    truth = base * kind.relative + kind.lo + d.t * (kind.hi - kind.lo)
    lower = max(lo_limit, truth - (0.2 + 1.8 * d.below) * kind.span)
    upper = min(hi_limit, truth + (0.2 + 1.8 * d.above) * kind.span)
    start = None if d.start is None else lower + (0.02 + 0.96 * d.start) * (upper - lower)
    if d.no_lower and kind.open_lower:
        lower = -math.inf if lo_limit == -math.inf else lo_limit
    if d.no_upper and kind.open_upper:
        upper = math.inf if hi_limit == math.inf else hi_limit
    prior, chi2 = None, 0.0
    if d.prior is not None:
        offset, width = d.prior
        sigma = (0.05 + 1.95 * width) * kind.span
        prior, chi2 = (truth + offset * sigma, sigma), offset**2
    return fit.Unknown(kind.path, lower, upper, start, prior), truth, chi2


def build(path_set: PathSet, problems):
    """The cases (each with its truth), unknowns and evidence of ``problems`` (one batch), and each problem's
    truth vector and chi^2 at the truth (its priors' offsets). The evidence is the engine's own results at the
    truth, solved in one call (``ks_jax.solve``)."""
    cases, unknowns, truths, chi2 = [], [], [], []
    for p in problems:
        case = case_from_dict(path_set.template(np.random.default_rng(p.case_seed)))
        inputs, us, xs, c2 = case.inputs, [], [], 0.0
        for kind, d in zip(path_set.unknowns, p.draws):
            u, x, c = _unknown(kind, float(get_input(case.inputs, kind.path)), d)
            inputs = set_input(inputs, kind.path, x)
            us.append(u)
            xs.append(x)
            c2 += c
        cases.append(dataclasses.replace(case, inputs=inputs))
        unknowns.append(us)
        truths.append(xs)
        chi2.append(c2)
    solutions = solve(cases, smoothing=SMOOTHING)
    evidence = [[fit.Evidence(path, float(get_output(s.result, path)), sigma * p.sigma_scale)
                 for path, sigma in path_set.evidence] for s, p in zip(solutions, problems)]
    return cases, unknowns, evidence, np.array(truths), np.array(chi2)


NAN_WORD = re.compile(r"\bnan\b", re.IGNORECASE)


def check_well_formed(r, unknowns, posterior=False):
    """What every fit must give, whatever its problem: a finite chi^2, a report in plain words, JSON without NaN,
    estimates within the bounds, and (with a posterior) every unknown's summary."""
    paths = [u.path for u in unknowns]
    assert math.isfinite(r.chi2), (r.case_name, r.chi2, r.status)
    text = text_report(r)
    assert text.startswith(f"Reconstruction: {r.case_name}") and "chi^2 = " in text, text
    assert all(p in text for p in paths) and not NAN_WORD.search(text), text
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert list(d["estimate"]) == paths and d["chi2"] == pytest.approx(r.chi2)
    for u in unknowns:
        assert u.lower <= r.estimate[u.path] <= u.upper, (u, r.estimate[u.path])
    if posterior:
        post = r.posterior
        assert post is not None and list(post.summary) == paths and post.samples.shape[-1] == len(paths)
        for p, s in post.summary.items():
            assert all(math.isfinite(s[k]) for k in ("mean", "std", "q025", "q50", "q975", "ess")), (p, s)
            assert math.isfinite(s["rhat"]) == (post.chains > 1)
        assert set(d["posterior"]["unknowns"]) == set(paths)


def fit_batch(path_set: PathSet, problems, posterior=0):
    cases, unknowns, evidence, truths, chi2 = build(path_set, problems)
    results = fit.reconstruct_batch(cases, unknowns, evidence, starts=path_set.starts, posterior=posterior, chains=2)
    return results, unknowns, truths, chi2


# ---------------------------------------------------------------------------------------------------------
# hypothesis: any numbers


UNIT = st.floats(0.0, 1.0)


@st.composite
def draws(draw, kind: Kind):
    prior = draw(st.one_of(st.none(), st.tuples(st.floats(-2.0, 2.0), UNIT)))
    return Draw(draw(UNIT), draw(UNIT), draw(UNIT), draw(st.booleans()), draw(st.booleans()),
                draw(st.one_of(st.none(), UNIT)), prior)


@st.composite
def problems(draw, path_set: PathSet):
    return Drawn(draw(st.integers(0, 2**16)), draw(st.floats(0.3, 3.0)),
                   tuple(draw(draws(k)) for k in path_set.unknowns))


@pytest.mark.parametrize("name", sorted(PATH_SETS))
@settings(max_examples=2, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.large_base_example])
@given(data=st.data())
def test_any_drawn_problem_gives_a_finite_fit_a_plain_report_and_valid_json(name, data):
    """Whatever the numbers of a problem (truth, bounds given or left out, start, prior, sigmas), its fit ends
    without an exception, with a finite chi^2, a report in plain words, JSON without NaN and estimates within the
    bounds; the problems of one unknown also draw a posterior (2 chains x 10 draws), with every unknown's summary
    and R-hat. Each example is a batch of ``BATCH`` drawn problems of one set of paths."""
    path_set = PATH_SETS[name]
    drawn = data.draw(st.lists(problems(path_set), min_size=BATCH, max_size=BATCH))
    posterior = 10 if name == "one" else 0
    results, unknowns, _, _ = fit_batch(path_set, drawn, posterior)
    for r, us in zip(results, unknowns):
        check_well_formed(r, us, posterior=bool(posterior))


# ---------------------------------------------------------------------------------------------------------
# a seeded batch: how often the truth is reached


def random_problem(rng, path_set: PathSet) -> Drawn:
    def one():
        prior = (rng.uniform(-2, 2), rng.random()) if rng.random() < 0.3 else None
        start = rng.random() if rng.random() < 0.3 else None
        return Draw(rng.random(), rng.random(), rng.random(), bool(rng.random() < 0.3), bool(rng.random() < 0.3),
                    start, prior)

    return Drawn(int(rng.integers(2**16)), float(rng.uniform(0.3, 3.0)), tuple(one() for _ in path_set.unknowns))


SEEDED = {"collision": 128, "one": 56, "motion": 16}  # 200 problems, in batches of BATCH


def test_at_least_99_percent_of_200_seeded_problems_reach_the_truths_chi2():
    """200 problems drawn by a seeded generator (as the hypothesis test draws them), fitted with the default
    rounds of starts: at least 99% end with a chi^2 no higher than the truth's (0 for noise-free evidence, plus
    the squared offsets of the priors' means in their sigmas) to ``REACH``; each fit is well formed. The misses
    are listed."""
    rng = np.random.default_rng(20240611)
    misses, total = [], 0
    for name, count in SEEDED.items():
        path_set = PATH_SETS[name]
        for _ in range(count // BATCH):
            drawn = [random_problem(rng, path_set) for _ in range(BATCH)]
            results, unknowns, truths, chi2 = fit_batch(path_set, drawn)
            for r, us, x, c2, p in zip(results, unknowns, truths, chi2, drawn):
                total += 1
                check_well_formed(r, us)
                if not r.chi2 <= c2 + REACH * (1 + c2):
                    misses.append(f"{name} #{total}: chi^2 {r.chi2:.4g} > {c2:.4g} at the truth "
                                  f"{dict(zip([u.path for u in us], np.round(x, 4)))}; estimate "
                                  f"{ {k: round(v, 4) for k, v in r.estimate.items()} }; {r.starts} starts, "
                                  f"{r.starts_at_best} at best; {p}")
    assert total == 200
    assert len(misses) <= 2, f"{len(misses)} of 200 missed the truth's chi^2:\n" + "\n".join(misses)
