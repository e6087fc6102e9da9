"""A case's motion to rest end to end: ``ks-jax solve --json`` against the straight skid's closed forms, a sweep
of the road's friction, and reconstructions from rest positions (docs/model.md, "Motion to rest")."""

import copy
import dataclasses
import json
import tomllib

import numpy as np
import pytest

import fit
import ks_jax
from ks_jax import units as U
from ks_jax.case import CaseError, case_from_dict, get_output, load_case
from ks_jax.units import G0
from samples import CASES, run_cli

SEED_TO_REST = CASES / "rest_seed_000.json"
SPIN_OUT = CASES / "tbone_spin_out.json"


@pytest.mark.slow
def test_solve_json_gives_each_skid_its_closed_form(capsys):
    """The seed chapter's rear-end crash, both cars locked after it: each slides straight on from its position at
    the exchange, along its course after, d = v^2 / (2 mu g) and t = v / (mu g) from its speed after (1e-3)."""
    code, out, _ = run_cli(capsys, "solve", str(SEED_TO_REST), "--json")
    assert code == 0
    data = json.loads(out)["cases"][0]
    raw = json.loads(SEED_TO_REST.read_text())
    mu = raw["road"]["friction"]
    for i, v in enumerate(data["vehicles"]):
        speed = v["speed_after"]
        d, t = speed ** 2 / (2 * mu * G0), speed / (mu * G0)
        x0 = float(raw["vehicles"][i]["position"][0].split()[0]) * U.FT
        np.testing.assert_allclose(v["distance_to_rest"], d, rtol=1e-3)
        np.testing.assert_allclose(v["time_to_rest"], t, rtol=1e-3)
        np.testing.assert_allclose(v["rest_position"], [x0 + d, 0.0], rtol=1e-3, atol=1e-9)
        assert v["rest_yaw"] == 0.0 and v["rotation_to_rest"] == 0.0 and v["at_rest"] is True
    code, panel, _ = run_cli(capsys, "solve", str(SEED_TO_REST))
    assert "rest position (x, y): at rest" in panel and "distance to rest (CG path)" in panel


@pytest.mark.slow
def test_a_vehicle_still_moving_at_the_time_limit_is_said_so(capsys):
    """The Saturn, struck from behind and rolling free, does not stop in 4 s; the Pontiac behind it, its wheels
    locked, does (and never reaches it again): the Saturn's at_rest is false, and a note says what to change."""
    raw = json.loads(SEED_TO_REST.read_text())
    raw["road"]["time_limit"] = "4.003 s"
    raw["vehicles"][0]["after"] = {"wheels": "free"}
    sol = ks_jax.solve(case_from_dict(raw))
    d = sol.to_dict()
    assert d["vehicles"][0]["at_rest"] is False and d["vehicles"][1]["at_rest"] is True
    assert len(d["exchanges"]) == 1
    np.testing.assert_allclose(d["vehicles"][0]["time_to_rest"], 4.005, rtol=1e-9)  # whole steps: 801
    assert any("vehicles[0] (Saturn L300) still moves at the time limit" in n and "road.time_limit" in n
               for n in d["notes"]), d.get("notes")


@pytest.mark.slow
def test_a_swept_road_friction_scales_the_skids_as_one_over_mu():
    """d = v^2 / (2 mu g): over a sweep of road.friction the distance times mu is the same, and equals the closed
    form from the speed after (the exchange does not depend on the road)."""
    case = load_case(SEED_TO_REST)
    result = ks_jax.sweep(case, {"road.friction": [0.4, 0.7, 1.0, 0.0, 12.0]},
                          outputs=["vehicles[0].distance_to_rest", "vehicles[1].distance_to_rest",
                                   "vehicles[0].speed_after"])
    # a friction of 0 or above 10 breaks the road's rule: those rows are invalid, with no numbers
    assert ([ks_jax.status_text(c) for c in result["status"][3:]]
            == [ks_jax.status_text(ks_jax.model.types.INVALID_MOTION)] * 2)
    assert np.all(np.isnan(np.asarray(result["vehicles[0].distance_to_rest"][3:], float)))
    result = {k: np.asarray(result[k])[:3] for k in ("vehicles[0].distance_to_rest", "vehicles[1].distance_to_rest",
                                                       "vehicles[0].speed_after")}
    mus = np.array([0.4, 0.7, 1.0])
    v = np.asarray(result["vehicles[0].speed_after"], float)
    np.testing.assert_allclose(np.asarray(result["vehicles[0].distance_to_rest"], float) * mus, v ** 2 / (2 * G0),
                               rtol=1e-3)
    assert np.ptp(np.asarray(result["vehicles[1].distance_to_rest"], float) * mus) < 1e-3
    # an infinite track (a set_input, a fit's step) breaks the rule too: its row is invalid, not NaN unexplained
    broken = ks_jax.set_input(case.inputs, "vehicles[1].track", float("inf"))
    # solved as the case's own program (solve_inputs called outside jit would compile each operation apart)
    sol = ks_jax.solve(dataclasses.replace(case, inputs=broken))
    assert sol.status.startswith("invalid: an input of the motion to rest"), sol.status
    with pytest.raises(CaseError, match="has no road"):
        ks_jax.sweep(load_case(CASES / "seed_000_saturn_pontiac.json"), {"road.friction": mus})


@pytest.mark.slow
def test_noise_free_rest_positions_and_crush_recover_both_speeds():
    """The spin-out's rest positions computed at 25 and 35 mph, and its crush, as evidence with the speeds unknown
    (started at 20 and 30 mph): the fit finds both to 1e-3 relative."""
    raw = json.loads(SPIN_OUT.read_text())
    truth = ks_jax.solve(case_from_dict(raw)).result
    paths = [f"vehicles[{i}].rest_position[{k}]" for i in (0, 1) for k in (0, 1)] + ["vehicles[0].crush",
                                                                                      "vehicles[1].crush"]
    evidence = [{"quantity": p, "value": float(get_output(truth, p)), "sigma": 0.3 if "rest" in p else 0.03}
                for p in paths]
    raw["vehicles"][0]["speed"], raw["vehicles"][1]["speed"] = "20 mph", "30 mph"
    unknowns = {f"vehicles[{i}].speed": {"bounds": ["5 mph", "60 mph"]} for i in (0, 1)}
    res = fit.reconstruct(case_from_dict(raw), unknowns, evidence)
    assert res.converged and res.unidentified == []
    np.testing.assert_allclose(res.estimate["vehicles[0].speed"], 25 * U.MPH, rtol=1e-3)
    np.testing.assert_allclose(res.estimate["vehicles[1].speed"], 35 * U.MPH, rtol=1e-3)


@pytest.mark.slow
def test_rest_positions_of_an_inline_crash_cannot_separate_speed_from_road_friction():
    """The struck car at rest before an inline crash: both speeds after are proportional to the striking car's
    speed v, so both skids are proportional to v^2 / mu and only that ratio is determined. The fit says so, and
    names both unknowns."""
    raw = copy.deepcopy(json.loads(SEED_TO_REST.read_text()))
    raw["vehicles"][0]["speed"] = "0 mph"
    truth = ks_jax.solve(case_from_dict(raw)).result
    evidence = [{"quantity": p, "value": float(get_output(truth, p)), "sigma": 0.1}
                for p in ("vehicles[0].rest_position[0]", "vehicles[1].rest_position[0]")]
    unknowns = {"vehicles[1].speed": {"bounds": ["5 mph", "60 mph"]}, "road.friction": {"bounds": [0.3, 1.0]}}
    res = fit.reconstruct(case_from_dict(raw), unknowns, evidence, starts=4)
    said = " ".join(res.unidentified)
    assert res.unidentified and "vehicles[1].speed" in said and "road.friction" in said, res.unidentified


@pytest.mark.slow
def test_front_wheels_locked_slide_at_the_deceleration_their_load_transfer_gives():
    """The second seed chapter's Kia brakes its front wheels only, its rears rolling: braking moves load m a h / L
    onto the locked fronts, so the deceleration a solves m a = (mu - f) (m g (L - c) / L + m a h / L) + f m g, c the
    CG's distance to the front axle, and the straight slide is v^2 / (2 a) long. The model's load transfer uses the
    step before's deceleration (none in the first step), within 2e-3 of the closed form here.

    In the shipped case the Kia, slowing less than the locked Lucid, catches it again (later exchanges); here the
    Lucid's wheels roll free, so that the Kia never reaches it, and then the Kia's wheels lock too, so that the Lucid
    skids away from it: one exchange each, as the closed forms assume."""
    raw = tomllib.loads((CASES / "rest_seed_001.toml").read_text())
    raw["vehicles"][0]["after"] = {"wheels": "free"}
    case = case_from_dict(raw)
    sol = ks_jax.solve(case)
    assert int(sol.result.interactions.count) == 1
    after = case.inputs.road.vehicles[1]
    mu, f, g = float(case.inputs.road.friction), float(after.rolling_resistance), G0
    L, c, h = float(after.wheelbase), float(after.cg_to_front_axle), float(case.inputs.vehicles[1].cg_height)
    a = g * ((mu - f) * (L - c) / L + f) / (1 - (mu - f) * h / L)
    v = float(sol.result.vehicles[1].speed_after)
    rest = sol.result.rest[1]
    np.testing.assert_allclose(float(rest.distance_to_rest), v * v / (2 * a), rtol=2e-3)
    np.testing.assert_allclose(float(rest.time_to_rest), v / a, rtol=2e-3)
    # the Lucid, all four locked: the straight skid, load transfer or not
    raw["vehicles"][0]["after"], raw["vehicles"][1]["after"] = {"wheels": "locked"}, {"wheels": "locked"}
    sol = ks_jax.solve(case_from_dict(raw))
    assert int(sol.result.interactions.count) == 1
    v0 = float(sol.result.vehicles[0].speed_after)
    np.testing.assert_allclose(float(sol.result.rest[0].distance_to_rest), v0 * v0 / (2 * mu * g), rtol=1e-3)
