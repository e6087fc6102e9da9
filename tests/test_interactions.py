"""Contact interactions through the case layer (docs/model.md, "Contact interactions"): case files, paths, the JSON,
the panel and the notes, against independent references: the first exchange's own results, linear momentum on a
frictionless road, the exchanges' records against the watched motion's own bookkeeping, and the wall's face.
The physics itself is checked against closed forms in tests/model/test_interaction.py."""

import copy
import json
import math

import numpy as np
import pytest

import fit
import ks_jax
from ks_jax.case import CaseError, CaseWarning, case_from_dict, get_output, load_case
from samples import CASES, run_cli

TBONE = json.loads((CASES / "tbone_spin_out.json").read_text())


def frictionless(raw, limit="1.5 s"):
    """``raw`` on a road of friction 0 (free wheels, no rolling resistance): between exchanges nothing acts."""
    raw = copy.deepcopy(raw)
    raw["road"] = {"friction": 0, "time_limit": limit}
    for v in raw["vehicles"]:
        v["after"] = {"wheels": "free"}
    return raw


def solved(raw):
    return ks_jax.solve(case_from_dict(raw)).to_dict()


@pytest.mark.slow
def test_a_case_of_one_exchange_reports_it_as_its_exchanges():
    """Without a road, and with one that parts the cars for good, the one exchange is ``exchanges[0]``: its results
    are the contact's, the energy total its energy loss, each vehicle's cumulative delta-V its delta-V."""
    for name in ("seed_000_saturn_pontiac.json", "rest_seed_000.json"):
        out = ks_jax.solve(load_case(CASES / name)).to_dict()
        (only,) = out["exchanges"]
        assert only["between"] == [0, 1] and only["interaction"] == 0 and only["time"] == 0.0
        for key, value in out["contact"].items():
            if key != "time":
                assert only[key] == value, (name, key)
        assert out["energy_loss_total"] == pytest.approx(out["contact"]["energy_loss"], rel=1e-12)
        for k, v in enumerate(out["vehicles"]):
            np.testing.assert_allclose(v["delta_v_cumulative"], v["delta_v"], rtol=1e-12, atol=1e-12)
            assert v["delta_v_cumulative_magnitude"] == pytest.approx(v["delta_v_magnitude"], rel=1e-9)
            assert v["delta_v_cumulative_pdof"] == pytest.approx(v["pdof"], abs=1e-6)
            (inter,) = v["interactions"]
            assert inter["interaction"] == 0 and inter["exchanges"] == [0]
            np.testing.assert_allclose(inter["delta_v"], v["delta_v"], rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_momentum_is_kept_through_every_exchange_on_a_frictionless_road():
    """The spin-out on a road of friction 0: the pickup pushes into the sedan again after the first exchange. Nothing
    acts between exchanges, so the vehicles' total horizontal momentum after their last exchanges (read from the
    JSON's exchanges) is what it was before the first (read from the case); each cumulative delta-V is then the sum
    of its impulses over the mass."""
    raw = frictionless(TBONE)
    raw["interaction"] = {"max_exchanges": 64}
    out = solved(raw)
    assert len(out["exchanges"]) >= 2 and not any("max_exchanges" in n for n in out.get("notes", []))
    case = case_from_dict(raw)
    masses = [float(v.mass) for v in case.inputs.vehicles]
    before = sum(m * float(v.speed) * np.array([math.cos(float(v.course)), math.sin(float(v.course))])
                 for m, v in zip(masses, case.inputs.vehicles))
    last = {}
    for ex in out["exchanges"]:
        for v in ex["vehicles"]:
            last[v["vehicle"]] = np.asarray(v["velocity_after"][:2])
    after = sum(m * last[k] for k, m in enumerate(masses))
    np.testing.assert_allclose(after, before, rtol=1e-9, atol=1e-9 * np.abs(before).max())
    for v in out["vehicles"]:  # horizontally: the motion between exchanges is planar (vertical motion dropped)
        (first,) = [i for i in v["interactions"] if i["interaction"] == 0]
        np.testing.assert_allclose(first["delta_v_impulses"][:2], first["delta_v"][:2], rtol=1e-9, atol=1e-9)


@pytest.mark.slow
def test_cumulative_delta_v_is_the_velocity_change_across_the_interaction():
    """The spin-out on its dry road: the watched motion's own cumulative delta-V (traced, a path for sweeps and fits)
    is the change of velocity across the vehicle's first interaction that the exchanges' records give (after the
    last minus before the first), tyre forces between included, so that it differs from the sum of the impulses."""
    out = ks_jax.solve(load_case(CASES / "tbone_spin_out.json")).to_dict()
    assert len(out["exchanges"]) > 2 and "notes" not in out
    for k, v in enumerate(out["vehicles"]):
        mine = [ex for ex in out["exchanges"] if ex["interaction"] == 0]
        side = [next(x for x in ex["vehicles"] if x["vehicle"] == k) for ex in mine]
        change = np.asarray(side[-1]["velocity_after"]) - (np.asarray(side[0]["velocity_after"])
                                                           - np.asarray(side[0]["delta_v"]))
        np.testing.assert_allclose(v["delta_v_cumulative"], change, rtol=1e-9, atol=1e-9)
        assert v["delta_v_cumulative_magnitude"] == pytest.approx(np.linalg.norm(change), rel=1e-9)
        assert np.linalg.norm(np.asarray(v["interactions"][0]["delta_v_impulses"]) - change) > 1e-3


@pytest.mark.slow
def test_a_sedan_glancing_off_a_wall_slaps_it_with_its_rear():
    """The shipped wall case: after the first exchange the sedan's rear swings into the wall, a new contact
    interaction. Every exchange is with the wall, at its face (x = 6 m: an overlap with a wall lies between its
    face and the vehicle's outline, no deeper than the vehicle went in), and later in time than the one before."""
    out = ks_jax.solve(load_case(CASES / "wall_side_slap.json")).to_dict()
    exchanges = out["exchanges"]
    assert len(exchanges) >= 2
    assert all(ex["between"] == [0, "fixed[0]"] for ex in exchanges)
    assert exchanges[1]["interaction"] == 1 and exchanges[1]["time"] > 0.1
    assert np.all(np.diff([ex["time"] for ex in exchanges]) > 0)
    for ex in exchanges:
        assert 5.5 < ex["point"][0] <= 6.0 + 1e-9, ex["point"]
        assert ex["vehicles"][0]["energy_share"] == pytest.approx(ex["energy_loss"], rel=1e-12)
    assert out["energy_loss_total"] == pytest.approx(sum(ex["energy_loss"] for ex in exchanges), rel=1e-9)


@pytest.mark.slow
def test_later_exchanges_are_output_paths(capsys):
    """``exchanges[k].field``, the cumulative delta-V and the energy total read from a result as the JSON gives them;
    a sweep carries them, NaN in rows with fewer exchanges than k + 1."""
    case = load_case(CASES / "wall_side_slap.json")
    sol = ks_jax.solve(case)
    out = sol.to_dict()
    assert float(get_output(sol.result, "exchanges[1].impulse_magnitude")) == pytest.approx(
        out["exchanges"][1]["impulse_magnitude"], rel=1e-12)
    assert float(get_output(sol.result, "exchanges[1].time")) == pytest.approx(out["exchanges"][1]["time"])
    assert float(get_output(sol.result, "vehicles[0].delta_v_cumulative[1]")) == pytest.approx(
        out["vehicles"][0]["delta_v_cumulative"][1], rel=1e-12)
    assert float(get_output(sol.result, "energy_loss_total")) == pytest.approx(out["energy_loss_total"], rel=1e-12)
    speed = float(case.inputs.vehicles[0].speed)
    count = len(out["exchanges"])
    result = ks_jax.sweep(case, {"vehicles[0].speed": [0.3 * speed, speed]},
                          outputs=["exchanges[1].impulse_magnitude", f"exchanges[{count}].impulse_magnitude",
                                   "vehicles[0].delta_v_cumulative_magnitude", "energy_loss_total"])
    values = result.outputs
    assert values["exchanges[1].impulse_magnitude"][1] == pytest.approx(out["exchanges"][1]["impulse_magnitude"],
                                                                        rel=1e-6)
    assert values["vehicles[0].delta_v_cumulative_magnitude"][1] == pytest.approx(
        out["vehicles"][0]["delta_v_cumulative_magnitude"], rel=1e-6)
    assert math.isnan(values[f"exchanges[{count}].impulse_magnitude"][1])  # one slot past the case's exchanges
    # the slower row as the case solved at that speed gives it: its second exchange, or NaN where it has none
    slow = ks_jax.solve(case_from_dict({**case.raw, "vehicles": [{**case.raw["vehicles"][0],
                                                                  "speed": f"{0.3 * speed} m/s"}]})).to_dict()
    expected = slow["exchanges"][1]["impulse_magnitude"] if len(slow["exchanges"]) > 1 else math.nan
    got = values["exchanges[1].impulse_magnitude"][0]
    assert (math.isnan(got) and math.isnan(expected)) or got == pytest.approx(expected, rel=1e-6), (got, expected)
    code, text, err = run_cli(capsys, "solve", str(CASES / "wall_side_slap.json"))
    assert code == 0 and "next contact" in text and "#1 at" in text


@pytest.mark.slow
def test_a_fit_reads_cumulative_delta_v_as_evidence():
    """Without a road the cumulative delta-V is the exchange's delta-V: a fit to it finds what a fit to the delta-V
    finds (the seed reconstruction's unknown speed)."""
    case = load_case(CASES / "fit_seed_001.toml") if (CASES / "fit_seed_001.toml").exists() else \
        load_case(CASES / "fit_seed_001.json")
    raw = case.raw
    evidence = [dict(e) for e in raw["evidence"]]
    renamed = [dict(e, quantity=e["quantity"].replace("delta_v_magnitude", "delta_v_cumulative_magnitude"))
               for e in evidence]
    assert renamed != evidence
    a = fit.reconstruct(case, raw["unknowns"], evidence, starts=2)
    b = fit.reconstruct(case, raw["unknowns"], renamed, starts=2)
    for path, value in a.estimate.items():
        assert b.estimate[path] == pytest.approx(value, rel=1e-6)


@pytest.mark.parametrize("entry, words", [
    ({"restitution": 2}, "interaction.restitution = 2: must be in [-1, 1]"),
    ({"friction": -0.1}, "interaction.friction = -0.1: must be >= 0"),
    ({"max_exchanges": 0}, "interaction.max_exchanges = 0: must be a whole number from 1 to 64"),
    ({"max_exchanges": 2.5}, "interaction.max_exchanges = 2.5"),
    ({"approach_tolerance": "0 m/s"}, "interaction.approach_tolerance = '0 m/s': must be positive"),
])
def test_bad_interaction_entries_are_refused_by_name(entry, words):
    raw = copy.deepcopy(TBONE)
    raw["interaction"] = entry
    with pytest.raises(CaseError) as err:
        case_from_dict(raw)
    assert words in str(err.value)


def test_an_interaction_without_a_road_or_an_unknown_field_is_ignored_with_a_warning_and_no_friction_is_allowed():
    raw = copy.deepcopy(TBONE)
    raw["interaction"] = {"restitution": 0.1, "colour": "red"}
    with pytest.warns(CaseWarning, match="interaction.colour: unknown field"):
        case_from_dict(raw)
    del raw["road"]
    with pytest.warns(CaseWarning) as said:
        assert case_from_dict(raw).inputs.interaction is None
    words = [str(w.message) for w in said]
    assert [w for w in words if "interaction: later exchanges happen while the bodies move on" in w]
    assert [w for w in words if "interaction.colour: unknown field" in w]
    for k in (0, 1):  # without a road, what describes each vehicle's motion to rest is said to be ignored too
        assert [w for w in words if f"vehicles[{k}]: wheelbase" in w and "a case without \"road\"" in w], words
    case = case_from_dict(frictionless(TBONE))
    assert float(case.inputs.road.friction) == 0.0
    assert all(float(a.rolling_resistance) == 0.0 for a in case.inputs.road.vehicles)
    raw = frictionless(TBONE)
    raw["vehicles"][0]["after"]["rolling_resistance"] = 0.01
    with pytest.raises(CaseError, match="rolling_resistance"):
        case_from_dict(raw)


@pytest.mark.slow
def test_running_out_of_exchanges_and_ending_inside_each_other_are_said():
    """The Kia pushes the Lucid in small exchanges until both rest: with room for 2 exchanges only, the count stops
    while they still push, and the JSON and the panel say so; where they rest, their outlines overlap by their
    crush, which the notes give in metres."""
    raw = json.loads(json.dumps(__import__("tomllib").loads((CASES / "rest_seed_001.toml").read_text())))
    raw["interaction"] = {"max_exchanges": 2}
    sol = ks_jax.solve(case_from_dict(raw))
    out = sol.to_dict()
    assert len(out["exchanges"]) == 2
    said = " ".join(out["notes"])
    assert "stopped at interaction.max_exchanges (2)" in said and "overlap where they end" in said
    assert "stopped at interaction.max_exchanges (2)" in " ".join(ks_jax.report.text_report(sol).split())
