"""Crush energy from a crush profile and the damaged side's stiffness (``ks_jax.model.crush``, docs/model.md, "Crush
energy") against its closed forms, the six-point formula written out, the CRASH3 manual's sample run, finite
differences and the exchange itself; the case file's keys and their rules; the results through ``ks-jax solve
--json`` and the panel."""

import copy
import itertools
import json
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax import units as U
from ks_jax.case import CaseError, case_from_dict
from ks_jax.case.crush import CrushProfile
from ks_jax.model import crush as C
from ks_jax.plot import top_view
from ks_jax.solve.crush import energy_and_sigma
from fit import Evidence, parse_evidence
from samples import run_cli

ROOT = Path(__file__).resolve().parents[2]
A, B = 300 * U.LBF / U.INCH, 90 * U.LBF / U.INCH**2  # N/m, N/m^2


def energy(width, depths, a=A, b=B, alpha=0.0):
    return float(C.crush_energy(jnp.asarray(width), jnp.asarray(depths, float), jnp.asarray(a), jnp.asarray(b),
                                alpha))


@pytest.mark.parametrize("n", [2, 4, 6])
def test_a_uniform_profile_is_the_closed_form(n):
    """A uniform crush C over a width L: E = L (A C + B C^2 / 2 + G), G = A^2 / (2 B), whatever the number of
    points; and the threshold alone (C = 0) is L G."""
    width, depth = 1.6, 0.31
    g = A * A / (2 * B)
    assert energy(width, [depth] * n) == pytest.approx(width * (A * depth + B * depth**2 / 2 + g), rel=1e-13)
    assert energy(width, [0.0] * n) == pytest.approx(width * g, rel=1e-13)


def six_point(width, c, a, b, alpha):
    """docs/model.md's six-point formula, written out term by term."""
    c1, c2, c3, c4, c5, c6 = c
    g = a * a / (2 * b)
    linear = a / 2 * (c1 + 2 * c2 + 2 * c3 + 2 * c4 + 2 * c5 + c6)
    square = b / 6 * (c1**2 + 2 * c2**2 + 2 * c3**2 + 2 * c4**2 + 2 * c5**2 + c6**2
                      + c1 * c2 + c2 * c3 + c3 * c4 + c4 * c5 + c5 * c6)
    return width / 5 * (linear + square + 5 * g) * (1 + math.tan(alpha) ** 2)


def integral(width, c, a, b):
    """The energy as its definition: the integral over the width of A C + B C^2 / 2 + G, the crush C(x) linear
    between the profile's points, by the trapezoid rule on 60,001 points."""
    x = np.linspace(0.0, width, 60001)
    depth = np.interp(x, np.linspace(0.0, width, len(c)), c)
    f = a * depth + b * depth * depth / 2 + a * a / (2 * b)
    return float(np.sum((f[1:] + f[:-1]) / 2 * np.diff(x)))


def test_any_profile_is_its_integral_the_six_point_formula_and_the_same_read_from_either_end():
    """Random profiles of 2, 4 and 6 points, stiffnesses and force angles: the energy is the integral that
    defines it (times 1 + tan^2 alpha), for six points the six-point formula written out, and reversing the
    profile (measured from the other end) changes nothing."""
    rng = np.random.default_rng(3)
    for n in (2, 4, 6, 6, 6):
        width, c = rng.uniform(0.5, 2.0), rng.uniform(0.0, 0.6, n)
        a, b, alpha = rng.uniform(2e4, 9e4), rng.uniform(2e5, 2e6), rng.uniform(-0.7, 0.7)
        got = energy(width, c, a, b, alpha)
        assert got == pytest.approx(integral(width, c, a, b) * (1 + math.tan(alpha) ** 2), rel=1e-8)
        if n == 6:
            assert got == pytest.approx(six_point(width, c, a, b, alpha), rel=1e-12)
        assert energy(width, c[::-1], a, b, alpha) == pytest.approx(got, rel=1e-13)


def test_the_crash3_manuals_sample_run():
    """The sample run of NHTSA's CRASH3 User's Guide and Technical Manual (section 5, its damage summary; the
    stiffness of category 4 in Table 8-2). Its vehicle 2, struck in the side: A = 143 lb/in, B = 50 lb/in^2,
    L = 84.5 in, C1..C6 = 6.2, 8.3, 9.2, 5.9, 4.4, 0.8 in, the force 45 deg off the side's normal (a factor of 2),
    printed 31,220.8 ft-lb; its vehicle 1, struck in the front: A = 356 lb/in, B = 34 lb/in^2, L = 73.0 in,
    C1, C2 = 2.7, 3.6 in, printed 19,245.3 ft-lb with no direction correction. The printout gives its inputs to
    0.1 in and 1 lb/in (its program held more digits): each printed energy lies within what those roundings allow
    (every length and depth +-0.05 in, A and B +-0.5), and the computed one within 0.4 % and 0.3 % of it (its G
    is A^2 / 2B of the printed A and B; the printout's G, from its own digits, is 203 and 1,874 lb against 204.5
    and 1,863.8)."""
    def ft_lbf(a, b, width, c, alpha):
        return energy(width * U.INCH, np.asarray(c) * U.INCH, a * U.LBF / U.INCH, b * U.LBF / U.INCH**2,
                      math.radians(alpha)) / U.FT_LBF

    for a, b, width, c, alpha, printed, rel in ((143, 50, 84.5, [6.2, 8.3, 9.2, 5.9, 4.4, 0.8], 45, 31220.8, 4e-3),
                                               (356, 34, 73.0, [2.7, 3.6], 0, 19245.3, 3e-3)):
        assert ft_lbf(a, b, width, c, alpha) == pytest.approx(printed, rel=rel)
        ends = [ft_lbf(a + da, b + db, width + dl, np.asarray(c) + dl, alpha)
                for da, db, dl in itertools.product((-0.5, 0.5), (-0.5, 0.5), (-0.05, 0.05))]
        assert min(ends) <= printed <= max(ends), (min(ends), printed, max(ends))


def test_the_energys_sigma_is_its_derivatives_times_the_sigmas():
    """``energy_and_sigma``'s first-order sigma: the root sum of squares of central differences of the energy in
    the width, each depth, A and B, times their sigmas."""
    p = CrushProfile(1.5, (0.1, 0.25, 0.3, 0.2, 0.12, 0.02), A, B, 0.2, 0.02, 0.01, 0.1 * A, 0.15 * B)
    value, sigma = energy_and_sigma(p)
    assert value == pytest.approx(energy(p.width, p.depths, A, B, 0.2), rel=1e-14)

    def moved(k, h):
        x = [p.width, *p.depths, p.a, p.b]
        x[k] += h
        return energy(x[0], x[1:7], x[7], x[8], 0.2)

    sigmas = [p.width_sigma] + [p.depth_sigma] * 6 + [p.a_sigma, p.b_sigma]
    steps = [1e-6] * 7 + [1e-6 * A, 1e-6 * B]
    terms = [(moved(k, h) - moved(k, -h)) / (2 * h) * s for k, (h, s) in enumerate(zip(steps, sigmas))]
    assert sigma == pytest.approx(math.sqrt(sum(t * t for t in terms)), rel=1e-8)


SEDAN = {"stiffness": {"A": "300 lbf/in", "B": "90 lbf/in^2"},
         "crush_profile": {"width": "60 in", "depths": ["10 in"] * 6}}
PICKUP = {"stiffness": {"A": "400 lbf/in", "B": "120 lbf/in^2", "A_sigma": "40 lbf/in"},
          "crush_profile": {"width": "70 in", "depths": ["6 in", "8 in", "8 in", "5 in"]}}


def head_on(first=SEDAN, second=PICKUP):
    """docs/validation/inline.json's head-on (a central inline impact, restitution 0) with crush profiles."""
    raw = json.loads((ROOT / "docs/validation/inline.json").read_text())["cases"][1]
    assert raw["name"] == "I2 head-on" and raw["contact"]["restitution"] == 0
    for v, more in zip(raw["vehicles"], (first, second)):
        v.update(copy.deepcopy(more))
    return raw


def solve_json(tmp_path, capsys, *cases):
    path = tmp_path / "crush.json"
    path.write_text(json.dumps({"cases": list(cases)}))
    code, text, err = run_cli(capsys, "solve", str(path), "--json")
    return code, json.loads(text)["cases"], err


@pytest.mark.slow
def test_crush_results_through_solve_json_and_the_central_cross_check(tmp_path, capsys):
    """``ks-jax solve --json`` of a head-on with both profiles: the sedan's uniform 10 in over 60 in against
    A = 300 lbf/in, B = 90 lbf/in^2 is L (A C + B C^2 / 2 + G) = 60 (3000 + 4500 + 500) in lbf = 40,000 ft lbf
    exactly; each EES is sqrt(2 E / m); each CRASH3 delta-V is sqrt(2 (E1 + E2) m_other / (m (m1 + m2))) worked
    here; the pickup's sigma is its A_sigma times dE/dA = L (mean C + A / B) (G = A^2 / 2B). And the cross-check:
    this impact is central, inline and plastic, so CRASH3's delta-V fed the exchange's own energy loss (split in
    any proportion) is the exchange's delta-V of each vehicle."""
    code, (out,), err = solve_json(tmp_path, capsys, head_on())
    assert code == 0, err
    sedan, pickup = out["vehicles"]
    m1, m2 = 1300.0, 2100.0
    assert sedan["crush_energy"] == pytest.approx(40000 * U.FT_LBF, rel=1e-12)
    assert sedan["crush_energy_sigma"] == 0.0
    c = np.array([6, 8, 8, 5]) * U.INCH
    strips = (c[:-1] + c[1:]) / 2
    width, a, b = 70 * U.INCH, 400 * U.LBF / U.INCH, 120 * U.LBF / U.INCH**2
    assert pickup["crush_energy_sigma"] == pytest.approx(40 * U.LBF / U.INCH * width * (strips.mean() + a / b),
                                                         rel=1e-12)
    e1, e2 = sedan["crush_energy"], pickup["crush_energy"]
    for v, e, m, other in ((sedan, e1, m1, m2), (pickup, e2, m2, m1)):
        assert v["crush_ees"] == pytest.approx(math.sqrt(2 * e / m), rel=1e-12)
        assert v["crush_delta_v"] == pytest.approx(math.sqrt(2 * (e1 + e2) * other / (m * (m1 + m2))), rel=1e-12)
    loss = out["contact"]["energy_loss"]
    # both have profiles: the energy loss is shared by crush energy, in the EES and the exchange's energy shares
    shares = {v["vehicle"]: v["energy_share"] for v in out["exchanges"][0]["vehicles"]}
    for k, (v, e, m) in enumerate(((sedan, e1, m1), (pickup, e2, m2))):
        assert 0.5 * m * v["ees"] ** 2 == pytest.approx(loss * e / (e1 + e2), rel=1e-12)
        assert shares[k] == pytest.approx(loss * e / (e1 + e2), rel=1e-12)
    for share in (0.3, 0.5, 0.8):
        dv = C.crush_delta_v(jnp.asarray(share * loss), jnp.asarray((1 - share) * loss), m1, m2)
        assert float(dv[0]) == pytest.approx(sedan["delta_v_magnitude"], rel=1e-9)
        assert float(dv[1]) == pytest.approx(pickup["delta_v_magnitude"], rel=1e-9)


@pytest.mark.slow
def test_one_profile_a_fixed_object_and_the_panel(tmp_path, capsys):
    """A profile on one vehicle only: its energy and EES, no CRASH3 delta-V (the other's energy is unknown), and
    nulls for the other; the exchange's EES is shared by the box overlap's crushes as without any profile. Into a
    wall (docs/validation/wall.json's W1), which takes no energy: the CRASH3 delta-V is the EES. The panel shows the
    box overlap as a model quantity, which split the EES used, and the measured profile's rows."""
    wall = json.loads((ROOT / "docs/validation/wall.json").read_text())["cases"][0]
    wall["vehicles"][0].update(copy.deepcopy(SEDAN))
    code, (one, into_wall, plain), err = solve_json(tmp_path, capsys, head_on(second={}), wall, head_on({}, {}))
    assert code == 0, err
    sedan, pickup = one["vehicles"]
    assert [v["ees"] for v in one["vehicles"]] == [v["ees"] for v in plain["vehicles"]]
    assert sedan["crush_energy"] == pytest.approx(40000 * U.FT_LBF, rel=1e-12) and sedan["crush_delta_v"] is None
    assert all(pickup[k] is None for k in ("crush_energy", "crush_energy_sigma", "crush_ees", "crush_delta_v"))
    car = into_wall["vehicles"][0]
    assert car["crush_delta_v"] == car["crush_ees"] == pytest.approx(math.sqrt(2 * 40000 * U.FT_LBF / 1400), rel=1e-12)
    path = tmp_path / "crush.json"
    code, text, err = run_cli(capsys, "solve", str(path))
    assert code == 0, err
    assert "crush, box overlap (model)" in text and "crush energy (measured profile)" in text
    assert "EES (by box overlap)" in text
    assert "40,000 ft lbf" in text and "delta-V from crush (CRASH3)" in text


@pytest.mark.parametrize("change, field, rule", [
    (lambda v: v.pop("stiffness"), "vehicles[0].stiffness", "missing field"),
    (lambda v: v["crush_profile"].update(depths=["1 in"] * 5), "vehicles[0].crush_profile.depths", "2, 4 or 6"),
    (lambda v: v["crush_profile"]["depths"].__setitem__(2, "-1 in"), "vehicles[0].crush_profile.depths[2]", ">= 0"),
    (lambda v: v["crush_profile"].update(pdof="60 deg"), "vehicles[0].crush_profile.pdof", "45"),
    (lambda v: v["stiffness"].update(B=0), "vehicles[0].stiffness.B", "must be positive"),
    (lambda v: v["stiffness"].update(A="300 lbf"), "vehicles[0].stiffness.A", "'300 lbf'"),
    (lambda v: v["crush_profile"].update(width="30 ft"), "vehicles[0].crush_profile.width", "vehicle's length"),
    (lambda v: v["stiffness"].update(A_sigma="-1 lbf/in"), "vehicles[0].stiffness.A_sigma", ">= 0"),
])
def test_a_bad_crush_entry_is_refused_naming_its_field_and_rule(change, field, rule):
    raw = head_on()
    change(raw["vehicles"][0])
    with pytest.raises(CaseError) as err:
        case_from_dict(raw)
    assert field in str(err.value) and rule in str(err.value) and "I2 head-on" in str(err.value)


@pytest.mark.slow
def test_a_bad_crush_entry_loses_only_its_case(tmp_path, capsys):
    """In a file of two cases, the one with a bad profile is reported with its field; the other is solved."""
    bad = head_on()
    bad["name"] = "bad profile"
    bad["vehicles"][0]["crush_profile"]["depths"] = ["1 in"] * 3
    code, (first, second), err = solve_json(tmp_path, capsys, bad, head_on())
    assert first["contact"]["status"].startswith("invalid") and "crush_profile.depths" in first["contact"]["status"]
    assert second["contact"]["status"] == "ok" and second["vehicles"][0]["crush_energy"] > 0


def test_the_top_view_draws_each_profile_to_scale_on_its_damaged_side():
    """The head-on's profiles drawn where the vehicles are: the car (yaw 180 deg, CG at x = 2.1 m, 1.9 m to its
    front) has its front face at x = 0.2 m and its uniform 10 in of crush at x = 0.2 + 0.254 m, over the profile's
    60 in centred on the centroid's foot (y = 0), C1 at its left end (at -y, the car facing -x); the pickup (yaw 0,
    CG at x = -2.3 m, 2.6 m to its front) its 6, 8, 8, 5 in set back from x = 0.3 m over 70 in, C1 at +y."""
    plt = pytest.importorskip("matplotlib.pyplot")
    ax = top_view(ks_jax.solve(case_from_dict(head_on())))
    drawn = {line.get_gid(): line for line in ax.get_lines() if line.get_gid()}
    car, pickup = (np.column_stack(drawn[f"crush-profile-{i}"].get_data()) for i in (0, 1))
    np.testing.assert_allclose(car[:, 0], 0.2 + 10 * U.INCH, atol=1e-9)
    np.testing.assert_allclose(car[:, 1], np.linspace(-30, 30, 6) * U.INCH, atol=1e-9)
    np.testing.assert_allclose(pickup[:, 0], 0.3 - np.array([6, 8, 8, 5]) * U.INCH, atol=1e-9)
    np.testing.assert_allclose(pickup[:, 1], np.linspace(35, -35, 4) * U.INCH, atol=1e-9)
    assert drawn["crush-profile-0"].get_label() == "car: measured crush profile (front, to scale)"
    plt.close(ax.figure)


def fit_json(tmp_path, capsys, raw):
    path = tmp_path / "crush_fit.json"
    path.write_text(json.dumps(raw))
    code, text, err = run_cli(capsys, "fit", str(path), "--json")
    assert code == 0, err
    (out,) = json.loads(text)["cases"]
    return out


@pytest.mark.slow
def test_a_fit_from_crush_energy_alone_is_the_closed_form(tmp_path, capsys):
    """The head-on (central, inline, restitution 0) with the pickup's speed unknown and both crush energies as the
    only evidence (the sedan's as a value and sigma, the pickup's from its profile and A_sigma): both vehicles have
    profiles, so the exchange shares its energy loss E = mu u^2 / 2 (mu = m1 m2 / (m1 + m2), u = 15 m/s + v) in
    proportion to them, and both residuals vanish where E is their sum: v = sqrt(2 (E1 + E2) / mu) - 15 m/s."""
    raw = head_on()
    raw["unknowns"] = {"vehicles[1].speed": {"bounds": ["0 mph", "80 mph"]}}
    raw["evidence"] = [{"quantity": "vehicles[0].crush_energy", "value": "40000 ft*lbf", "sigma": "4000 ft*lbf"},
                       {"quantity": "vehicles[1].crush_energy"}]
    out = fit_json(tmp_path, capsys, raw)
    e2, _ = energy_and_sigma(case_from_dict(head_on()).crush[1])
    mu = 1300.0 * 2100.0 / 3400.0
    want = math.sqrt(2 * (40000 * U.FT_LBF + e2) / mu) - 15.0
    assert out["estimate"]["vehicles[1].speed"] == pytest.approx(want, rel=1e-6)
    assert out["chi2"] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.slow
def test_crush_energy_beside_delta_v_says_how_far_they_agree(tmp_path, capsys):
    """The same head-on, the pickup's speed unknown (12 m/s in truth), the car's delta-V measured at the truth's
    (m2 / (m1 + m2) 27 m/s, sigma 0.05 m/s) and both crush energies 10 % above the truth's shares of its energy loss
    mu u^2 / 2 (shared by the profiles' crush energies, sigma 5 %): the fit follows the tight delta-V, and its
    evidence table sets the crush's EES (sqrt(2 E / m)) beside the exchange's, sqrt(1.1) = 1.049 times it, its
    residual (fitted - measured) / sigma about -1.8."""
    raw = head_on()
    raw["unknowns"] = {"vehicles[1].speed": {"bounds": ["0 mph", "80 mph"]}}
    m1, m2, mu = 1300.0, 2100.0, 1300.0 * 2100.0 / 3400.0
    weights = [energy_and_sigma(p)[0] for p in case_from_dict(head_on()).crush]
    loss = 0.5 * mu * 27.0**2
    raw["evidence"] = [{"quantity": "vehicles[0].delta_v_magnitude", "value": f"{m2 / (m1 + m2) * 27.0!r} m/s",
                        "sigma": "0.05 m/s"}]
    for i, w in enumerate(weights):
        e = 1.1 * loss * w / sum(weights)
        raw["evidence"].append({"quantity": f"vehicles[{i}].crush_energy", "value": f"{e!r} J",
                                "sigma": f"{0.05 * e!r} J"})
    out = fit_json(tmp_path, capsys, raw)
    assert out["estimate"]["vehicles[1].speed"] == pytest.approx(12.0, abs=0.1)
    for i, m in enumerate((m1, m2)):
        path = f"vehicles[{i}].ees"
        assert out["measured"][path] == pytest.approx(math.sqrt(2 * 1.1 * loss * weights[i] / sum(weights) / m),
                                                      rel=1e-12)
        assert out["measured"][path] / out["fitted"][path] == pytest.approx(math.sqrt(1.1), rel=0.01)
        assert out["residuals"][path] == pytest.approx((out["fitted"][path] - out["measured"][path])
                                                       / out["sigma"][path], rel=1e-9)


@pytest.mark.parametrize("second, entry, words", [
    ({}, {"quantity": "vehicles[1].crush_energy"}, "vehicles[1] has no crush profile"),
    (PICKUP, {"quantity": "vehicles[0].crush_energy"}, "gives no uncertainty"),
    (PICKUP, {"quantity": "vehicles[1].crush_energy", "value": "40000 ft*lbf"}, "give both value and sigma"),
    (PICKUP, {"quantity": "vehicles[2].crush_energy", "value": "1 J", "sigma": "1 J"}, "not a vehicle of the first"),
    (PICKUP, {"quantity": "vehicles[1].crush_energy", "value": "-5 J", "sigma": "1 J"}, "must be positive"),
    (PICKUP, {"quantity": "vehicles[1].crush_energy", "time": "1 s"}, "has no time"),
])
def test_bad_crush_energy_evidence_is_refused_naming_the_entry(second, entry, words):
    """Crush-energy evidence the fit cannot use: a vehicle without a profile and no value, a profile without any
    sigma, a value without a sigma, a vehicle outside the first exchange, a negative energy, a time."""
    case = case_from_dict(head_on(second=second))
    with pytest.raises(CaseError) as err:
        parse_evidence(case, [entry])
    assert words in str(err.value) and "I2 head-on" in str(err.value) and "evidence[0]" in str(err.value)


def test_crush_energy_evidence_is_the_ees_it_gives():
    """In Python and in a file alike: E and sigma_E become EES = sqrt(2 E / m) and sigma_E / sqrt(2 m E)."""
    case = case_from_dict(head_on())
    e, s = 60000.0, 3000.0
    entry = {"quantity": "vehicles[1].crush_energy", "value": f"{e} J", "sigma": f"{s} J"}
    (from_file,) = parse_evidence(case, [entry])
    (from_python,) = parse_evidence(case, [Evidence("vehicles[1].crush_energy", e, s)])
    assert from_file == from_python
    assert from_file.path == "vehicles[1].ees"
    assert from_file.value == pytest.approx(math.sqrt(2 * e / 2100.0), rel=1e-15)
    assert from_file.sigma == pytest.approx(s / math.sqrt(2 * 2100.0 * e), rel=1e-15)
