"""The posterior by NUTS (``fit.reconstruct(posterior=N)``, ``fit.posterior``) against the Laplace approximation
where the posterior is Gaussian, and against the half-normal that a bound makes of it where the estimate sits on
the bound. Both cases share one problem (the seed chapter's rear impact: the Kia's speed and restitution from
both delta-Vs and both speeds after, noise-free), so that the sampler compiles once."""

import dataclasses
import importlib
import json
import math

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
import pytest

import fit
from fit.arrays import case_arrays
from fit.posterior import run_chains
from fit.report import text_report
import ks_jax.cli.fit
from ks_jax.cli import main
from ks_jax.cli.fit import posterior_path, save_posterior
from ks_jax.case import get_output, load_case, set_input
from ks_jax.solve import solve
from samples import CASES, reference_jit

pytestmark = pytest.mark.slow  # samplers and batches of fits: each compiles programs of its own

EVIDENCE = [("vehicles[0].delta_v_magnitude", 0.15), ("vehicles[1].delta_v_magnitude", 0.15),
            ("vehicles[0].speed_after", 0.15), ("vehicles[1].speed_after", 0.15)]
DRAWS = 1000  # per chain: over 100 seeds the chains' R-hat stayed below 1.007 and their ESS above 1000

# Compiled once each with the quick settings (``samples.reference_jit``; XLA's defaults take 2-4 times as long to
# compile the same arithmetic): the sampler's gradient (which users run inside the sampler's program, ``_segment``,
# compiled with them on a CPU), the log-density it is checked against, and the two samplers compared.
_value_and_gradient = reference_jit(fit.posterior._value_and_gradient, static_argnums=0)
_log_density = reference_jit(fit.posterior.log_density, static_argnums=0)
_run_chains = reference_jit(run_chains, static_argnums=(0, 3, 4))


def _fit(restitution, seed=3, target_acceptance=0.8):
    """The seed case with ``restitution``, its evidence the engine's own values, refitted with the Kia's speed
    and restitution unknown, and 4 chains x ``DRAWS`` draws of their posterior, adapted toward
    ``target_acceptance``."""
    case = load_case(CASES / "fit_seed_001.json")
    case = dataclasses.replace(case, inputs=set_input(case.inputs, "contact.restitution", restitution))
    result = solve(case, smoothing=1e-3).result
    evidence = [fit.Evidence(p, float(get_output(result, p)), s) for p, s in EVIDENCE]
    unknowns = [fit.Unknown("vehicles[1].speed", 0.0, 30.0), fit.Unknown("contact.restitution", 0.0, 0.6)]
    return fit.reconstruct(case, unknowns, evidence, posterior=DRAWS, seed=seed, target_acceptance=target_acceptance)


@pytest.fixture(scope="module")
def gaussian():
    return _fit(0.3)


# At the bound, the draws' density in the unbounded coordinate falls steeply on one side. Over 100 seeds (each a
# different path of the chains, as another machine's rounding gives; ``benchmarks/posterior_paths.py``), adapted
# toward Stan's mean acceptance of 0.8 the chains of 35 diverged, up to 9 transitions of 4000; toward 0.9 those of
# 3, one transition each. Both drew the half-normal within the checks below.
BOUND_ACCEPTANCE = 0.9


@pytest.fixture(scope="module")
def at_bound():
    return _fit(0.0, target_acceptance=BOUND_ACCEPTANCE)


def test_a_well_determined_posterior_is_the_laplace_gaussian(gaussian):
    """Restitution 0.3, far from its bounds [0, 0.6]: the posterior mean is the estimate and the posterior std the
    Laplace standard error, within their Monte Carlo errors (std / sqrt(ESS), std / sqrt(2 ESS)); the 16-84% span
    is 2 standard errors; the chains agree (R-hat < 1.01) and nothing diverged."""
    r = gaussian
    post = r.posterior
    assert post.chains == 4 and post.draws == DRAWS and post.samples.shape == (4, DRAWS, 2)
    assert post.divergences == 0 and post.warnings == []
    for path, s in post.summary.items():
        se = r.std[path]
        assert s["rhat"] < 1.01 and s["ess"] > 400
        assert abs(s["mean"] - r.estimate[path]) < 4 * s["std"] / math.sqrt(s["ess"]), path
        assert abs(s["std"] - se) < 4 * se / math.sqrt(2 * s["ess"]), path
        assert abs((s["q84"] - s["q16"]) / (2 * se) - 1) < 0.1, path
    d = r.to_dict()["posterior"]
    assert d["divergences"] == 0 and set(d["unknowns"]["contact.restitution"]) == {
        "mean", "std", "q025", "q16", "q50", "q84", "q975", "rhat", "ess"}


def test_restitution_on_its_bound_has_the_half_normal_posterior_that_laplace_misses(at_bound):
    """Restitution 0 (the truth) on its lower bound: the likelihood is a Gaussian in restitution of width sigma
    (the Laplace standard error, which ignores the bound), and the uniform prior cuts it at 0. Its posterior is
    then half-normal: mean sigma sqrt(2/pi), median 0.674 sigma, 97.5% quantile 2.241 sigma, std
    sigma sqrt(1 - 2/pi), where Laplace's interval would be 0 +/- 1.96 sigma, half of it below the bound. Each
    within its Monte Carlo error (a quantile's: sqrt(p (1 - p) / ESS) over the density there; the std's from the
    half-normal's fourth central moment mu4: sqrt((mu4 - var^2) / (4 var ESS)), about 1.2 times the normal's
    std / sqrt(2 ESS)). Adapted toward a mean acceptance of ``BOUND_ACCEPTANCE``, at most one transition in a
    thousand diverges, and the warnings count any that did."""
    r = at_bound
    sigma = r.std["contact.restitution"]
    s = r.posterior.summary["contact.restitution"]
    assert r.estimate["contact.restitution"] < 1e-9 and any("contact.restitution" in b for b in r.at_bound)
    draws = r.posterior.samples[:, :, 1]
    post = r.posterior
    assert np.all(draws >= 0.0) and s["rhat"] < 1.01 and post.divergences <= post.chains * post.draws / 1000
    assert post.target_acceptance == BOUND_ACCEPTANCE == r.to_dict()["posterior"]["target_acceptance"]
    assert any(f"{post.divergences} divergent" in w for w in post.warnings) == (post.divergences > 0)
    ess = s["ess"]
    assert abs(s["mean"] - sigma * math.sqrt(2 / math.pi)) < 4 * s["std"] / math.sqrt(ess)
    var, mu4 = (1 - 2 / math.pi) * sigma ** 2, (3 - 4 / math.pi - 12 / math.pi ** 2) * sigma ** 4
    assert abs(s["std"] - math.sqrt(var)) < 4 * math.sqrt((mu4 - var * var) / (4 * var * ess))
    for key, p, z in (("q50", 0.5, 0.6745), ("q975", 0.975, 2.2414)):
        density = 2 * math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) / sigma  # the half-normal's, at its quantile
        assert abs(s[key] - z * sigma) < 4 * math.sqrt(p * (1 - p) / ess) / density, key
    assert s["q025"] > 0 > r.estimate["contact.restitution"] - 1.96 * sigma  # Laplace's interval crosses the bound


@pytest.mark.parametrize("target", [0.8, 0.9])
def test_the_one_scan_sampler_draws_what_blackjax_window_adaptation_then_nuts_draw(target):
    """``run_chains`` adapts and draws in one scan of one NUTS transition (so that it compiles once); run as
    BlackJAX's own two steps (``window_adaptation(nuts, ..., target_acceptance_rate=target).run`` on a chain's first
    key, then a scan of ``nuts`` at the adapted step size and mass matrix on its second), the same keys give the
    same draws and step sizes, here on a correlated Gaussian whose scales differ by 1e4 (so that the mass matrix
    matters), at Stan's target acceptance and at a higher one (the same program: the target is an argument)."""
    blackjax = pytest.importorskip("blackjax")
    scale = np.sqrt([1.0, 100.0, 0.01])
    precision = np.linalg.inv(np.array([[1.0, 0.8, 0.0], [0.8, 2.0, 0.3], [0.0, 0.3, 0.5]]) * np.outer(scale, scale))
    density = lambda z: -0.5 * z @ precision @ z  # noqa: E731
    keys, z0 = jax.random.split(jax.random.key(1), 2), jnp.array([[0.1, 2.0, 0.0], [0.3, -1.0, 0.01]])
    warmup, draws = 150, 50

    def blackjax_chain(key, start):
        adapt_key, draw_key = jax.random.split(key)
        (state, tuned), _ = blackjax.window_adaptation(blackjax.nuts, density, target_acceptance_rate=target).run(
            adapt_key, start, warmup)
        kernel = blackjax.nuts(density, **tuned)
        step = lambda state, k: (kernel.step(k, state)[0],) * 2  # noqa: E731
        return jax.lax.scan(step, state, jax.random.split(draw_key, draws))[1].position, tuned["step_size"]

    zs, divergent, step_size = _run_chains(density, keys, z0, draws, warmup, target)
    expected, expected_step = reference_jit(jax.vmap(blackjax_chain))(keys, z0)
    assert zs.shape == (2, draws, 3) and divergent.shape == (2, draws)
    np.testing.assert_allclose(step_size, expected_step, rtol=1e-12)
    np.testing.assert_allclose(zs, expected, rtol=1e-12, atol=1e-12)


def test_with_rest_positions_the_gradient_is_forward_mode_through_the_motions_while_loop():
    """Rest positions as evidence: the sampler's gradient of the log-density is taken in forward mode, one
    tangent per unknown, through the motion's while loop (which stops when the vehicles rest), and equals the
    central differences of the log-density (step 1e-5 in z) to 1e-6 of its size."""
    case = load_case(CASES / "fit_rest_positions.json")
    unknowns, evidence, problem = fit.reconstruction._prepare(case, None, None)
    a = case_arrays(case, unknowns, evidence, np.float64)
    d = jax.tree_util.tree_map(jnp.asarray, a)
    assert problem.motion is not None and not problem.motion.reverse
    z = jnp.asarray(fit.problem.to_z(np.array([25.0, 35.0]) * 0.44704, a.lo, a.hi))
    smoothing = jnp.asarray(1e-3)
    value, gradient = _value_and_gradient(problem, z, d, smoothing)

    def density(q):
        return _log_density(problem, q, d, smoothing)

    assert float(value) == pytest.approx(float(density(z)), rel=1e-12)
    h = 1e-5
    central = [(float(density(z.at[j].add(h))) - float(density(z.at[j].add(-h)))) / (2 * h) for j in range(2)]
    np.testing.assert_allclose(gradient, central, rtol=1e-6, atol=1e-6 * float(np.max(np.abs(central))))


def test_a_seeded_posterior_draws_the_same_again_and_another_seed_does_not(gaussian):
    again = _fit(0.3)
    np.testing.assert_array_equal(again.posterior.samples, gaussian.posterior.samples)
    other = _fit(0.3, seed=4)
    assert not np.array_equal(other.posterior.samples, gaussian.posterior.samples)


def test_the_panel_shows_the_posterior_and_bad_draws_are_refused(gaussian, capsys, monkeypatch):
    """The panel's posterior rows give each unknown's mean, quantiles, R-hat and ESS in the trade's units; ``ks-jax
    fit --posterior -1``, ``--chains 0`` and a ``--target-acceptance`` outside (0, 1) are refused before any fit,
    naming the option and the rule; ``--target-acceptance`` reaches the fit."""
    text = text_report(gaussian)
    (row,) = [line for line in text.splitlines() if line.strip().startswith("vehicles[1].speed") and "R-hat" in line]
    s = gaussian.posterior.summary["vehicles[1].speed"]
    assert "mph" in row and f"R-hat {s['rhat']:.3f}" in row and f"ESS {s['ess']:.0f}" in row
    assert ("Posterior (NUTS, 4 chains x 1000 draws after 1000 adaptation steps toward acceptance 0.8; 0 divergent)"
            in text)
    for option in (["--posterior", "-1"], ["--posterior", "10", "--chains", "0"]):
        assert main(["fit", str(CASES / "fit_seed_001.json"), *option]) == 2
        assert "draws must be >= 0 and chains >= 1" in capsys.readouterr().err
    for value, words in (("1", "1: the target acceptance must be in (0, 1)"), ("x", "'x' is not a number")):
        with pytest.raises(SystemExit) as usage:
            main(["fit", str(CASES / "fit_seed_001.json"), "--posterior", "10", "--target-acceptance", value])
        assert usage.value.code == 2 and words in capsys.readouterr().err
    given = []
    monkeypatch.setattr(ks_jax.cli.fit, "reconstruct", lambda case, **kw: given.append(kw) or gaussian)
    assert main(["fit", str(CASES / "fit_seed_001.json"), "--posterior", "10", "--target-acceptance", "0.95"]) == 0
    assert given[0]["target_acceptance"] == 0.95 and given[0]["posterior"] == 10


def test_the_corner_plot_is_drawn_in_the_trades_units_beside_the_top_view(gaussian, tmp_path):
    """``ks-jax fit --posterior N --plot FILE`` writes the corner plot to FILE_posterior (of FILE's type): the
    speed's axis in mph, restitution without a unit; the draws are the posterior's, divided by the unit."""
    assert posterior_path(tmp_path / "case.png") == str(tmp_path / "case_posterior.png")
    assert posterior_path("case.svg", 1) == "case_posterior_2.svg"
    path = save_posterior(gaussian, tmp_path / "corner.svg")
    text = path.read_text()
    assert "vehicles[1].speed [mph]" in text and "contact.restitution" in text


def test_without_blackjax_the_posterior_is_refused_before_any_fit(monkeypatch, capsys):
    """Where the 'posterior' extra is not installed, ``ks-jax fit --posterior`` exits 2 with a line naming the
    extra, before fitting, and ``reconstruct(posterior=N)`` raises ImportError naming it."""
    real = importlib.import_module

    def missing(name, *args):
        if name.startswith("blackjax"):
            raise ImportError(f"No module named '{name}'")
        return real(name, *args)

    monkeypatch.setattr(importlib, "import_module", missing)
    assert main(["fit", str(CASES / "fit_seed_001.json"), "--posterior", "10"]) == 2
    err = capsys.readouterr().err
    assert "--posterior: the posterior needs BlackJAX (the 'posterior' extra): pip install 'ks-jax[posterior]'" in err
    assert "Traceback" not in err
    with pytest.raises(ImportError, match="posterior' extra"):
        fit.reconstruct(load_case(CASES / "fit_seed_001.json"), posterior=10)


# One unknown, the Kia's speed, whose evidence is itself (an EDR's pre-impact speed) and a Gaussian prior on it: the
# posterior is the product of two Gaussians in the speed (the bounds 0 and 30 m/s lie 38 sigma away), with
# precision 1/EDR_SIGMA^2 + 1/PRIOR_SIGMA^2 and the precision-weighted mean of the two, in closed form.
EDR, EDR_SIGMA, PRIOR, PRIOR_SIGMA = 9.0, 0.3, 9.6, 0.4
ONE_PRECISION = 1 / EDR_SIGMA**2 + 1 / PRIOR_SIGMA**2
ONE_MEAN, ONE_STD = (EDR / EDR_SIGMA**2 + PRIOR / PRIOR_SIGMA**2) / ONE_PRECISION, ONE_PRECISION**-0.5
# per chain: over 100 seeds (``benchmarks/posterior_paths.py``) one chain's ESS was at least 94 and two chains' R-hat
# at most 1.013; at 200 draws the ESS of 17 seeds' single chain and of 2 seeds' pair was 50 or less, and one pair's
# R-hat 1.053
ONE_DRAWS = 500


def _one_unknown(chains):
    case = load_case(CASES / "fit_seed_001.json")
    unknowns = [fit.Unknown("vehicles[1].speed", 0.0, 30.0, prior=(PRIOR, PRIOR_SIGMA))]
    evidence = [fit.Evidence("vehicles[1].speed", EDR, EDR_SIGMA)]
    return fit.reconstruct(case, unknowns, evidence, posterior=ONE_DRAWS, chains=chains, seed=1)


def _assert_closed_form(post):
    s = post.summary["vehicles[1].speed"]
    ess = s["ess"]
    assert post.samples.shape == (post.chains, ONE_DRAWS, 1) and post.divergences == 0 and ess > 50
    assert abs(s["mean"] - ONE_MEAN) < 4 * ONE_STD / math.sqrt(ess)
    assert abs(s["std"] - ONE_STD) < 4 * ONE_STD / math.sqrt(2 * ess)
    assert abs(s["q50"] - ONE_MEAN) < 4 * 1.2533 * ONE_STD / math.sqrt(ess)  # the median's error: sqrt(pi/2) std


def test_a_posterior_of_one_unknown_is_its_closed_form_gaussian():
    """A single unknown (where BlackJAX's diagnostics squeeze to a number, not an array of one): 2 chains x 500
    draws give the closed-form posterior's mean, std and median within their Monte Carlo errors, an R-hat and an
    effective sample size as numbers; the Laplace estimate and standard error are the closed form's too."""
    r = _one_unknown(chains=2)
    assert r.estimate["vehicles[1].speed"] == pytest.approx(ONE_MEAN, rel=1e-9)
    assert r.std["vehicles[1].speed"] == pytest.approx(ONE_STD, rel=1e-9)
    post = r.posterior
    _assert_closed_form(post)
    s = post.summary["vehicles[1].speed"]
    assert isinstance(s["rhat"], float) and s["rhat"] < 1.05 and not any("R-hat" in w for w in post.warnings)
    assert json.loads(json.dumps(r.to_dict(), allow_nan=False))["posterior"]["unknowns"]["vehicles[1].speed"]["rhat"] \
        == pytest.approx(s["rhat"])
    assert f"R-hat {s['rhat']:.3f}, ESS {s['ess']:.0f}" in text_report(r)


def test_one_chain_has_no_r_hat_but_an_effective_sample_size():
    """R-hat compares chains: with one it is undefined, NaN in numbers, null in JSON (valid JSON, no NaN),
    "undefined" in the report, and a warning says that R-hat needs two or more chains. The chain's draws still
    follow the closed-form posterior, and its effective sample size is given."""
    r = _one_unknown(chains=1)
    post = r.posterior
    _assert_closed_form(post)
    s = post.summary["vehicles[1].speed"]
    assert math.isnan(s["rhat"]) and math.isfinite(s["ess"])
    (why,) = [w for w in post.warnings if "R-hat" in w]
    assert "R-hat needs two or more chains" in why
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))["posterior"]
    assert d["unknowns"]["vehicles[1].speed"]["rhat"] is None
    assert d["unknowns"]["vehicles[1].speed"]["ess"] == pytest.approx(s["ess"])
    assert why in d["warnings"]
    text = text_report(r)
    assert f"R-hat undefined, ESS {s['ess']:.0f}" in text and "nan" not in text.lower()
    assert "Posterior (NUTS, 1 chain x 500 draws after 500 adaptation steps" in text
    assert f"warning: {why}" in text
    # the same fit, had its chain never moved: the value where it stayed, no spread, and the warning
    stuck = fit.posterior.summarize(["vehicles[1].speed"], np.full((1, 200, 1), 20.0), 0, 200, 1, [1.0])
    text = text_report(dataclasses.replace(r, posterior=stuck))
    assert "where every chain stayed: no spread measured (below)" in text and "+/- 0 mph" not in text
    assert "warning: a chain never moved: vehicles[1].speed (every chain)" in text and "nan" not in text.lower()


def test_the_effective_sample_size_of_one_chain_is_that_of_its_autocorrelation():
    """An AR(1) chain x_t = phi x_(t-1) + e_t has the effective sample size N (1 - phi) / (1 + phi) (its integrated
    autocorrelation time is (1 + phi) / (1 - phi)); ``summarize`` gives it for one chain of one unknown and of
    three, within 10% (the estimate's own error at N = 20000 is about 3%), and R-hat is NaN for each. With one
    draw a chain has neither, and both are said."""
    rng = np.random.default_rng(2)
    N, phi = 20000, np.array([0.5, 0.0, -0.3])
    e = rng.standard_normal((N, 3))
    x = np.zeros((N, 3))
    for t in range(1, N):
        x[t] = phi * x[t - 1] + e[t]
    expected = N * (1 - phi) / (1 + phi)
    for cols in ([0], [0, 1, 2]):
        post = fit.posterior.summarize([f"u{j}" for j in cols], x[None][:, :, cols], 0, 0, 0, [1.0])
        for j in cols:
            s = post.summary[f"u{j}"]
            assert math.isnan(s["rhat"]) and s["ess"] == pytest.approx(expected[j], rel=0.1)
    post = fit.posterior.summarize(["u"], np.zeros((1, 1, 1)), 0, 0, 0, [1.0])
    assert math.isnan(post.summary["u"]["rhat"]) and math.isnan(post.summary["u"]["ess"])
    assert any("R-hat needs two or more chains" in w for w in post.warnings)
    assert any("effective sample size is undefined" in w for w in post.warnings)
    assert json.dumps(post.to_dict(), allow_nan=False)


def test_a_chain_that_never_moved_measures_no_spread():
    """A chain whose draws are all one value (the sampler refused every step) measures nothing of the spread: with
    one chain, or every chain, stuck on an unknown, its std, quantiles and effective sample size are undefined
    (null in JSON, no "+/- 0" in the panel) and a warning names it; with one chain of two stuck, the spread of
    both chains is still that of their draws, and the warning names the stuck chain."""
    rng = np.random.default_rng(4)
    moving = rng.standard_normal((1, 50, 1))
    stuck = np.full((1, 50, 1), 5.2)
    for x, spread in ((stuck, False), (np.concatenate([stuck, stuck + 0.1]), False),
                      (np.concatenate([moving, stuck]), True)):
        post = fit.posterior.summarize(["vehicles[1].length"], x, 0, 50, 0, [1.0] * len(x))
        s = post.summary["vehicles[1].length"]
        assert s["mean"] == pytest.approx(x.mean())
        assert [w for w in post.warnings if w.startswith("a chain never moved: vehicles[1].length")]
        if spread:
            assert s["std"] == pytest.approx(x.reshape(-1).std(ddof=1)) and "(chain 2)" in post.warnings[0]
        else:
            assert all(math.isnan(s[k]) for k in ("std", "q025", "q16", "q50", "q84", "q975", "ess"))
            assert "(every chain)" in post.warnings[0]
            d = post.to_dict()["unknowns"]["vehicles[1].length"]
            assert d["std"] is None and d["q50"] is None and d["mean"] == pytest.approx(x.mean())
    post = fit.posterior.summarize(["u"], moving, 0, 50, 0, [1.0])
    assert not any("never moved" in w for w in post.warnings)
    post = fit.posterior.summarize(["u"], moving[:, :1], 0, 50, 0, [1.0])  # one draw in all: no spread either
    assert math.isnan(post.summary["u"]["std"]) and math.isnan(post.summary["u"]["q975"])
    assert any(w.startswith("one draw in all measures no spread") for w in post.warnings)
