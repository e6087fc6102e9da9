"""The host's part of a batch of fits, in NumPy over all the batch's fits at once: the checks of the unknowns and
evidence (``fit.spec.check_batch``), the starts (``fit.starts``), the Laplace analysis
(``fit.uncertainty.analyse_batch``) and the size of a further round's calls. Each is checked against what it must
be for every fit of the batch on its own: each case checked alone, the Latin hypercube's strata, the closed-form
covariance (J^T J)^-1, and each fit analysed alone."""

import math

import numpy as np
import pytest

import fit
from fit.spec import PathChecks, check_batch, make_problem, parse_evidence, parse_unknowns
from fit.rounds import MORE_BLOCKS, more_block
from fit.rows import ROWS_PER_CALL_ELSEWHERE, fit_block
from fit.starts import START_SPREAD, starts
from fit.uncertainty import analyse_batch
from ks_jax import backend
from ks_jax.case import CaseError, load_case
from samples import CASES

PATHS = ["vehicles[0].speed", "vehicles[1].speed", "contact.restitution", "contact.point[0]"]
NAN, INF = math.nan, math.inf


def test_a_batchs_starts_are_each_fits_latin_hypercube_within_its_own_bounds():
    """Five fits with their own bounds, starts and priors, drawn at once. Where both bounds are given, the
    first start is the given start or the middle, and the other 15 starts of each fit put one draw in each of
    15 equal strata of its bounds' inner 96%; where a bound is missing, the draws are reflected into the bound
    that is given, about the prior's mean or the case's value, and spread by the prior's sigma or by at least
    ``START_SPREAD`` of the kind."""
    rng = np.random.default_rng(0)
    B, S = 5, 16
    lower = np.array([[0, 0, 0, -2.0]] * B) + rng.uniform(0, 1, (B, 4))
    upper = lower + rng.uniform(1, 30, (B, 4))
    lower[:, 1], upper[:, 1] = 5.0, INF  # vehicles[1].speed: a lower bound only
    start = np.full((B, 4), NAN)
    start[2, 0] = lower[2, 0] + 0.25 * (upper[2, 0] - lower[2, 0])
    prior_mean, prior_sigma = np.full((B, 4), NAN), np.full((B, 4), NAN)
    prior_mean[1, 1], prior_sigma[1, 1] = 20.0, 2.0
    current = np.full((B, 4), 12.0)
    x = starts(PATHS, lower, upper, start, prior_mean, prior_sigma, current, S, rng)
    assert x.shape == (B, S, 4)
    for i in range(B):
        for j in (0, 2, 3):
            lo, hi = lower[i, j], upper[i, j]
            first = start[i, j] if i == 2 and j == 0 else 0.5 * (lo + hi)
            assert x[i, 0, j] == pytest.approx(first, rel=1e-15)
            u = (x[i, 1:, j] - lo) / (hi - lo)
            assert np.all((u >= 0.02) & (u < 0.98))
            assert sorted(np.floor((u - 0.02) / 0.96 * (S - 1)).astype(int)) == list(range(S - 1))
        assert np.all(x[i, 1:, 1] >= 5.0)
    assert x[1, 0, 1] == 20.0 and x[0, 0, 1] == 12.0  # the prior's mean, else the case's value
    # spread about the first start: the prior's sigma (2 m/s), else START_SPREAD's 10 m/s (12 m/s is larger)
    assert np.std(x[1, 1:, 1]) < 4.0 and np.std(x[[0, 2, 3, 4], 1:, 1]) > START_SPREAD["velocity"] / 2


def test_a_fit_drawn_alone_draws_the_same_starts_in_a_batch_of_one():
    """Drawn as a batch of one, a fit's starts are those of the same seed: the batch keeps one fit's draws."""
    lower, upper = np.array([[0.0, 0.0, 0.0, -1.0]]), np.array([[40.0, 40.0, 0.6, 1.0]])
    none = np.full((1, 4), NAN)
    a = starts(PATHS, lower, upper, none, none, none, np.zeros((1, 4)), 8, np.random.default_rng(3))
    rng = np.random.default_rng(3)
    for j in range(4):  # the draws of one fit, unknown by unknown: a permutation of the strata, then offsets
        strata = (rng.permutation(7) + rng.random(7)) / 7
        np.testing.assert_array_equal(a[0, 1:, j], lower[0, j] + (upper[0, j] - lower[0, j]) * (0.02 + 0.96 * strata))


def _jacobians(rng, B, m, n):
    return rng.normal(size=(B, m + n, n))


def test_the_batch_analysis_is_the_closed_form_covariance_and_each_fit_analysed_alone():
    """Six fits of four unknowns and five pieces of evidence, analysed at once:
    - fits 0-2, full rank, no priors, within their bounds: the covariance is (J^T J)^-1 in the physical units,
      fit 2's evidence a million times more precise (what is small for one fit is not small for another);
    - fit 3: its evidence does not move contact.restitution (a zero column): that unknown is not determined,
      its standard error inf, its correlations NaN, and a sentence names it;
    - fit 4: the same zero column, with a prior of sigma 0.05 on it: the prior fixes it (standard error 0.05);
    - fit 5: a non-finite Jacobian: no uncertainty, said so.
    Every fit's analysis equals its analysis alone (a batch of one)."""
    rng = np.random.default_rng(1)
    B, m, n = 6, 5, 4
    J = _jacobians(rng, B, m, n) * [1.0, 1.0, 100.0, 10.0]  # per unit of each: restitution's range is 0.6
    J[:, m:] = 0.0  # no prior rows, except fit 4's below
    J[2] *= 1e6
    lower = np.tile([0.0, 0.0, 0.0, -1.0], (B, 1))
    upper = np.tile([40.0, 40.0, 0.6, 1.0], (B, 1))
    x = 0.5 * (lower + upper)
    prior_sigma, pw = np.full((B, n), NAN), np.zeros((B, n))
    J[3:5, :m, 2] = 0.0
    prior_sigma[4, 2], pw[4, 2] = 0.05, 1.0 / 0.05
    J[4, m + 2, 2] = pw[4, 2]
    J[5, 0, 0] = np.nan
    info = analyse_batch(PATHS, x, J, m, lower, upper, prior_sigma, pw, 1e-6)
    for i in range(3):
        cov = np.linalg.inv(J[i, :m].T @ J[i, :m])
        np.testing.assert_allclose(info.cov[i], cov, rtol=1e-9)
        np.testing.assert_allclose(info.std[i], np.sqrt(np.diag(cov)), rtol=1e-9)
        np.testing.assert_allclose(info.corr[i], cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov))),
                                   rtol=1e-9, atol=1e-12)
        assert not info.undetermined[i].any() and info.statements[i] == []
    assert list(info.undetermined[3]) == [False, False, True, False] and info.std[3, 2] == INF
    assert np.isnan(info.corr[3, 2]).all() and np.isinf(info.cov[3, :, 2]).all()
    assert [s for s in info.statements[3] if s.startswith("contact.restitution is not determined")]
    assert not info.undetermined[4].any() and info.std[4, 2] == pytest.approx(0.05, rel=1e-9)
    assert any("Only the prior on contact.restitution" in s for s in info.statements[4])
    assert np.isnan(info.std[5]).all() and "no finite derivatives" in info.statements[5][0]
    for i in range(B):
        alone = analyse_batch(PATHS, x[i:i + 1], J[i:i + 1], m, lower[i:i + 1], upper[i:i + 1],
                              prior_sigma[i:i + 1], pw[i:i + 1], 1e-6).row(0)
        batch = info.row(i)
        for k in ("cov", "std", "corr", "singular", "undetermined", "poorly"):
            np.testing.assert_allclose(getattr(batch, k), getattr(alone, k), rtol=1e-12, atol=1e-15,
                                       err_msg=f"fit {i}: {k}")
        assert batch.statements == alone.statements and batch.at_bound == alone.at_bound


def test_the_batch_analysis_says_which_fits_sit_on_a_bound_or_are_poorly_determined():
    """Two fits, each piece of evidence moved by one unknown: fit 0 is poorly determined in contact.point[0]
    (standard error 1/0.1 = 10 m, wider than a uniform guess within its 2 m of bounds: 2/sqrt(12) = 0.58 m) and
    sits on its lower speed bound; fit 1 (standard error 0.1 m) is neither."""
    m, n = 4, 4
    J = np.zeros((2, m + n, n))
    J[:, np.arange(4), np.arange(4)] = [[1.0, 1.0, 100.0, 0.1], [1.0, 1.0, 100.0, 10.0]]
    lower, upper = np.tile([0.0, 0.0, 0.0, -1.0], (2, 1)), np.tile([40.0, 40.0, 0.6, 1.0], (2, 1))
    x = np.array([[0.0, 20.0, 0.3, 0.0], [10.0, 20.0, 0.3, 0.0]])
    none = np.full((2, n), NAN)
    info = analyse_batch(PATHS, x, J, m, lower, upper, none, np.zeros((2, n)), 1e-6)
    assert list(info.poorly[0]) == [False, False, False, True] and not info.poorly[1].any()
    assert info.std[0, 3] == pytest.approx(10.0, rel=1e-12) and info.std[1, 3] == pytest.approx(0.1, rel=1e-12)
    assert [s for s in info.statements[0] if s.startswith("contact.point[0] is poorly determined")]
    assert len(info.at_bound[0]) == 1 and info.at_bound[0][0].startswith("vehicles[0].speed is at its lower")
    assert info.at_bound[1] == [] and info.statements[1] == []


def test_a_further_round_on_a_cpu_runs_in_calls_of_8_or_64_cases_and_on_an_accelerator_in_the_fits_block():
    """A round of 228 of 1000 cases x 8 starts: on a CPU, calls of 64 cases (a call's rows run one after
    another there, and few row counts compile few programs); on an accelerator, every round in the fit's own block
    (``fit_block``: the first round's rows up to ``ROWS_PER_CALL_ELSEWHERE`` a device), the first round's program."""
    cpu, accelerator = backend.Plan("cpu"), backend.Plan("accelerator")
    assert more_block(1000, 228, 8) == MORE_BLOCKS[-1] * 8 == 64 * 8
    assert more_block(1000, 5, 8) == 8 * 8 and more_block(4, 3, 8) == 4 * 8
    assert fit_block(1000 * 8, 0, cpu) is None and fit_block(1000 * 8, 0, accelerator) == 1000 * 8
    assert fit_block(10**6 * 8, 0, accelerator) == ROWS_PER_CALL_ELSEWHERE == 8000
    # over several devices each holds the rows one alone would; a CPU's calls are as on one
    assert fit_block(10**6 * 8, 0, accelerator, devices=4) == 4 * 8000
    assert fit_block(10**6 * 8, 0, cpu, devices=4) is None and fit_block(10**6 * 8, 5, cpu, devices=4) == 500


def test_a_batchs_checks_accept_and_refuse_each_case_as_its_own_checks_do():
    """200 cases of the seed chapter's fit with bounds, starts, priors, values and sigmas drawn from the edges of
    the rules (infinite, NaN, beyond 1e12, a speed's bound below 0, a restitution's above 1, a start outside, a
    sigma of 0 or 1e-10): ``check_batch`` checks all at once where each case alone is checked by
    ``parse_unknowns``, ``parse_evidence`` and ``make_problem``. It passes exactly the cases that pass alone, with
    the same bounds (a missing one taken as the input's own limit) and the same problem; it leaves the others to
    be checked alone, for their own error."""
    case = load_case(CASES / "fit_seed_001.json")
    rng = np.random.default_rng(5)
    edge = [0.0, -1.0, 0.5, 1.5, 30.0, INF, -INF, NAN, 2e12, -2e12, 1e-10]
    pick = lambda top: edge[rng.integers(len(edge))] if rng.random() < 0.06 else float(rng.uniform(0, top))  # noqa: E731
    paths = {"vehicles[1].speed": 30.0, "contact.restitution": 1.0}
    unknowns, evidence = [], []
    for _ in range(200):
        us = []
        for p, top in paths.items():
            lo, hi = sorted([pick(top), pick(top)]) if rng.random() < 0.9 else (pick(top), pick(top))
            start = pick(top) if rng.random() < 0.3 else None
            prior = (pick(top), pick(top)) if rng.random() < 0.3 else None
            us.append(fit.Unknown(p, lo, hi, start, prior))
        unknowns.append(us)
        evidence.append([fit.Evidence(p, pick(10.0), pick(1.0)) for p in ("vehicles[0].delta_v_magnitude",
                                                                           "vehicles[1].delta_v_magnitude")])
    batch = check_batch([case] * 200, unknowns, evidence, PathChecks())
    passed = 0
    for us, es, got in zip(unknowns, evidence, batch):
        try:
            alone_u, alone_e = parse_unknowns(case, us), parse_evidence(case, es)
            alone = (alone_u, alone_e, make_problem(case, alone_u, alone_e))
        except CaseError:
            assert got is None
            continue
        passed += 1
        assert got is not None
        assert [(u.path, u.lower, u.upper, u.start, u.prior) for u in got[0]] == \
            [(u.path, u.lower, u.upper, u.start, u.prior) for u in alone[0]]
        assert [(e.path, e.value, e.sigma) for e in got[1]] == [(e.path, e.value, e.sigma) for e in alone[1]]
        assert got[2] == alone[2]
    assert 10 < passed < 190  # both sides of the rules are drawn
