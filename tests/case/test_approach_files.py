"""A vehicle's approach in case files (docs/model.md, "The approach: the case file"): its phases read in SI with their
defaults and kinds, every rule refused with the case, the field, the value and the rule, a bad approach costing its
case only, and the output paths of the approach (vehicles[i].approach[k].speed, ...) parsed, read from a result and
refused where the case has no such phase. Loading and small eager computations only, but for one solve through
``ks-jax solve --json`` against the closed form of a locked straight skid (slow)."""

import copy
import json
import math
import re
import tomllib
import warnings

import numpy as np
import pytest

from fit.spec import evidence_kind, unknown_path
from ks_jax import units as U
from ks_jax.case import CaseError, CaseWarning, PathError, case_from_dict, cases_from_data, check_output_path
from ks_jax.case import get_output, output_kind, parse_path, path_key, without_approach
from ks_jax.case.outputs import CIRCULAR_OUTPUTS
from ks_jax.case.scale import xy_index
from ks_jax.model.approach import ApproachResult
from ks_jax.model.types import ExchangeResult
from ks_jax.sweeps.engine import check as check_sweep
from samples import CASES, run_cli

SPIN_OUT = json.loads((CASES / "tbone_spin_out.json").read_text())  # two cars on a road of friction 0.75
NAME = SPIN_OUT["name"]
# the sedan coasts 1.5 s, then brakes its fronts half way on a wet patch (friction 0.5, steered 2 deg left) and skids
# 48 ft with all four locked into the impact
PHASES = [{"wheels": "free", "duration": "1.5 s"},
          {"wheels": [0.5, 0.5, 0, 0], "steer": "2 deg", "distance": "300 in", "friction": 0.5,
           "rolling_resistance": 0.02},
          {"wheels": "locked", "distance": "48 ft"}]


def _with(change, base=SPIN_OUT):
    d = copy.deepcopy(base)
    change(d)
    return d


def _approach(phases=PHASES, vehicle=0):
    def change(d):
        d["vehicles"][vehicle]["approach"] = copy.deepcopy(phases)
    return change


def test_an_approach_reads_its_phases_in_si_with_their_kinds_and_defaults():
    """Phases in seconds, inches and feet reach ``CaseInputs.approach`` in SI, stacked over the phases, earliest
    first; their kinds reach ``Motion.approach``. Where a phase gives no wheels they are free, no steer, a rolling
    resistance of 0.015 and the road's friction; the other vehicle has none (None, ()); the case's state stays the
    state at the impact."""
    case = case_from_dict(_with(_approach()))
    assert case.motion.approach == (("duration", "distance", "distance"), ())
    a, none = case.inputs.approach
    assert none is None
    np.testing.assert_allclose(a.brake, [[0, 0, 0, 0], [0.5, 0.5, 0, 0], [1, 1, 1, 1]])
    np.testing.assert_allclose(a.steer, [0.0, math.radians(2), 0.0])
    np.testing.assert_allclose(a.rolling_resistance, [0.015, 0.02, 0.015])
    np.testing.assert_allclose(a.friction, [0.75, 0.5, 0.75])
    np.testing.assert_allclose(a.length, [1.5, 300 * 0.0254, 48 * U.FT], rtol=1e-12)
    for leaf in a:
        assert isinstance(leaf, np.ndarray) and leaf.dtype == np.float64 and leaf.shape[0] == 3
    plain = case_from_dict(SPIN_OUT)
    assert plain.inputs.approach == () and plain.motion.approach == ()
    for v, w in zip(case.inputs.vehicles, plain.inputs.vehicles):  # the state at the impact, as without
        for x, y in zip(v, w):
            np.testing.assert_array_equal(x, y)
    # a phase on a frictionless surface rolls without resistance unless it says otherwise
    on_ice = case_from_dict(_with(_approach([{"duration": 2, "friction": 0}], vehicle=1)))
    assert on_ice.motion.approach == ((), ("duration",))
    assert float(on_ice.inputs.approach[1].rolling_resistance[0]) == 0.0


def test_a_toml_file_gives_the_phases_as_an_array_of_tables():
    """``[[vehicles.approach]]`` after a ``[[vehicles]]`` table is that vehicle's list of phases."""
    text = """
[[vehicles]]
name = "Sedan"
[[vehicles.approach]]
wheels = "free"
duration = "1.5 s"
[[vehicles.approach]]
wheels = "locked"
distance = "48 ft"
"""
    (sedan,) = tomllib.loads(text)["vehicles"]
    case = case_from_dict(_with(lambda d: d["vehicles"][0].update(approach=sedan["approach"])))
    assert case.motion.approach == (("duration", "distance"), ())
    np.testing.assert_allclose(case.inputs.approach[0].length, [1.5, 48 * U.FT], rtol=1e-12)


def _phase(**kw):
    """Phase 0 of a one-phase approach of vehicles[0], a locked skid of 10 m, changed by ``kw`` (None: left out)."""
    phase = {"wheels": "locked", "distance": 10, **kw}
    return _approach([{k: v for k, v in phase.items() if v is not None}])


SEMI = {"name": "semi", "road": {"friction": 0.7},
        "vehicles": [{"name": "Tractor", "mass": 8000, "inertia": [5000, 30000, 30000], "length": 6.0, "width": 2.5,
                      "height": 3.5, "cg_to_front": 2.5, "cg_height": 1.0, "wheelbase": 3.8,
                      "cg_to_front_axle": 1.5, "position": [0, 0], "yaw": 0, "speed": 10},
                     {"name": "Trailer", "mass": 6000, "inertia": [5000, 30000, 30000], "length": 8.0,
                      "width": 2.5, "height": 3.5, "cg_to_front": 4.0, "cg_height": 1.0, "wheelbase": 5,
                      "cg_to_front_axle": 1, "yaw": 0, "hitch": {"to": 0, "point": [5, 0], "point_on_tow": [-2, 0]},
                      "approach": [{"wheels": "locked", "distance": 5}]},
                     {"name": "Car", "mass": 1500, "inertia": [500, 2400, 2600], "length": 4.6, "width": 1.8,
                      "height": 1.5, "cg_to_front": 2.0, "cg_height": 0.55, "position": [-8, -9], "yaw": 90,
                      "speed": 15}],
        "between": [2, 1], "contact": {"point": [-8, -5, 0.8], "normal": 90, "restitution": 0.1, "friction": 0.5}}

RULES = {  # name: (the case file's change, the field, the value as the message shows it, the rule)
    "not a list": (lambda d: d["vehicles"][0].update(approach={"distance": 10}), "vehicles[0].approach",
                   "{'distance': 10}", "must be a list of 1 to 8 phases"),
    "no phase": (_approach([]), "vehicles[0].approach", "[] (0 phases)", "must be a list of 1 to 8 phases"),
    "nine phases": (_approach([{"duration": 1}] * 9), "vehicles[0].approach", "(9 phases)",
                    "must be a list of 1 to 8 phases"),
    "a phase not a table": (_approach(["locked"]), "vehicles[0].approach[0]", "'locked'", "must be a table/object"),
    "neither": (_phase(distance=None), "vehicles[0].approach[0].duration", "missing field",
                "give duration, a time, or distance"),
    "both": (_phase(duration="1 s"), "vehicles[0].approach[0]", "duration = '1 s' and distance = 10",
             "give duration or distance, not both"),
    "duration 0": (_phase(distance=None, duration=0), "vehicles[0].approach[0].duration", "0",
                   "must be positive and at most 60 s"),
    "duration too long": (_phase(distance=None, duration="2 min"), "vehicles[0].approach[0].duration",
                          "'2 min' (120 s)", "must be positive and at most 60 s"),
    "duration infinite": (_phase(distance=None, duration=math.inf), "vehicles[0].approach[0].duration", "inf",
                          "must be a finite number"),
    "duration in metres": (_phase(distance=None, duration="3 m"), "vehicles[0].approach[0].duration", "'3 m'", ""),
    "distance negative": (_phase(distance="-3 ft"), "vehicles[0].approach[0].distance", "'-3 ft' (-0.9144 m)",
                          "must be positive and at most 1000 m"),
    "distance too long": (_phase(distance="1 mi"), "vehicles[0].approach[0].distance", "'1 mi' (1609 m)",
                          "must be positive and at most 1000 m"),
    "distance NaN": (_phase(distance=math.nan), "vehicles[0].approach[0].distance", "nan", "finite"),
    "distance in seconds": (_phase(distance="3 s"), "vehicles[0].approach[0].distance", "'3 s'", ""),
    "friction negative": (_phase(friction=-0.1), "vehicles[0].approach[0].friction", "-0.1", "must be >= 0"),
    "friction too high": (_phase(friction=11), "vehicles[0].approach[0].friction", "11", "at most 10"),
    "friction with a unit": (_phase(friction="0.5 m"), "vehicles[0].approach[0].friction", "'0.5 m'", ""),
    "wheels a word": (_phase(wheels="skidding"), "vehicles[0].approach[0].wheels", "'skidding'",
                      "must be \"free\", \"locked\" or four brake fractions"),
    "wheels three": (_phase(wheels=[0, 0, 0]), "vehicles[0].approach[0].wheels", "[0, 0, 0]", "four brake fractions"),
    "brake above 1": (_phase(wheels=[0.5, 1.2, 0, 0]), "vehicles[0].approach[0].wheels[1]", "1.2",
                      "a brake fraction must be in [0, 1]"),
    "steer": (_phase(steer="75 deg"), "vehicles[0].approach[0].steer", "'75 deg'", "within +-60 deg"),
    "rolling resistance above the road's": (_phase(rolling_resistance=0.8),
                                            "vehicles[0].approach[0].rolling_resistance", "0.8",
                                            "below the road's friction (0.75)"),
    "rolling resistance above the phase's": (_phase(rolling_resistance=0.6, friction=0.5),
                                             "vehicles[0].approach[0].rolling_resistance", "0.6",
                                             "below the phase's friction (0.5)"),
    "rolling resistance on ice": (_phase(rolling_resistance=0.01, friction=0),
                                  "vehicles[0].approach[0].rolling_resistance", "0.01", "or 0 on a road of friction 0"),
    "rolling resistance a word": (_phase(rolling_resistance="fast"), "vehicles[0].approach[0].rolling_resistance",
                                  "'fast'", ""),
    "a later phase": (_approach([{"duration": 1}, {"distance": 0}]), "vehicles[0].approach[1].distance", "0",
                      "must be positive"),
    "no road": (lambda d: (_approach()(d), d.pop("road")), "road", "missing field",
                "a case with an approach (vehicles[0].approach) needs a road"),
}


@pytest.mark.parametrize("name", list(RULES))
def test_a_bad_approach_is_refused_naming_the_case_field_value_and_rule(name):
    change, field, value, rule = RULES[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CaseWarning)  # a case without a road warns of its vehicles' wheels
        with pytest.raises(CaseError) as err:
            case_from_dict(_with(change))
    text = str(err.value)
    assert text.startswith(f"case '{NAME}': {field}") and value in text and rule in text, text


def test_a_towed_vehicle_is_refused_an_approach_of_its_own():
    """Articulated approaches are not modelled: a towed vehicle's approach is refused, naming its tow, whose
    approach it may have."""
    with pytest.raises(CaseError) as err:
        case_from_dict(SEMI)
    text = str(err.value)
    assert text.startswith("case 'semi': vehicles[1].approach = [{'wheels': 'locked', 'distance': 5}]: vehicles[1] "
                           "is towed by vehicles[0]"), text
    assert "give the tow's approach (vehicles[0].approach)" in text
    assert "articulated approaches are not modelled" in text
    def on_the_tow(d):
        d["vehicles"][0]["approach"] = d["vehicles"][1].pop("approach")
    case = case_from_dict(_with(on_the_tow, SEMI))
    assert case.motion.approach == (("distance",), (), ())
    assert case.motion.links == ((1, 0, "drawbar"),)


def test_an_unknown_key_of_a_phase_warns_and_a_bad_approach_costs_its_case_only():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        case = case_from_dict(_with(_approach([{"distance": 10, "wheel": "locked"}])))
    said = [str(w.message) for w in caught if issubclass(w.category, CaseWarning)]
    assert any(s.startswith(f"case '{NAME}': vehicles[0].approach[0].wheel: unknown field, ignored (known: ")
               and "distance" in s and "duration" in s for s in said), said
    np.testing.assert_allclose(case.inputs.approach[0].brake, [[0, 0, 0, 0]])  # the misspelt wheels: free
    bad = _with(_approach([{"wheels": "locked", "distance": "-48 ft"}]))
    good = _with(_approach([{"wheels": "locked", "distance": "48 ft"}], vehicle=1))
    cases = cases_from_data({"cases": [bad, good]})
    assert not cases[0].valid and "vehicles[0].approach[0].distance = '-48 ft'" in cases[0].error
    assert cases[1].valid and cases[1].motion.approach == ((), ("distance",))


def test_approach_output_paths_parse_with_their_kinds():
    """vehicles[i].approach[k].field[c]: the phase's index first, then a vector's component; units as the results'
    (yaw in degrees, a direction on the circle); the position's x and y are positions (moved with a scene)."""
    assert parse_path("vehicles[1].approach[2].speed") == ("vehicles", 1, "approach.speed", (2,))
    assert parse_path(" vehicles[0]. approach[1].position[1]") == ("vehicles", 0, "approach.position", (1, 1))
    kinds = {"speed": "velocity", "time": "time", "position[0]": "length", "position[1]": "length",
             "yaw": "degrees", "distance": "length"}
    for field, kind in kinds.items():
        assert check_output_path(f"vehicles[0].approach[3].{field}")[2] == f"approach.{field.split('[')[0]}"
        assert output_kind(f"vehicles[0].approach[3].{field}") == kind
    assert "approach.yaw" in CIRCULAR_OUTPUTS
    assert xy_index("vehicles[0].approach[2].position[1]") == 1 and xy_index("vehicles[0].approach[2].speed") is None


@pytest.mark.parametrize("path, words", [
    ("vehicles[0].approach", "an approach's results are named by phase"),
    ("vehicles[0].approach[1]", "an approach's results are named by phase"),
    ("vehicles[0].approach[0].velocity", "'velocity' is not a result of an approach phase; results are speed, time, "
                                         "position, yaw, distance"),
    ("vehicles[0].approach[0].position", "'position' is a vector: name a component, e.g. "
                                         "vehicles[0].approach[0].position[0]"),
    ("vehicles[0].approach[0].position[2]", "index out of range (0..1)"),
    ("vehicles[0].approach[0].speed[0]", "'speed' is a number and takes no index"),
    ("vehicles[0].approach[8].speed", "phase index must be 0 to 7 (an approach has at most 8 phases)"),
    ("vehicles[8].approach[0].speed", "vehicle index must be 0 to 7"),
])
def test_a_malformed_approach_output_path_is_refused(path, words):
    with pytest.raises(PathError) as err:
        check_output_path(path)
    assert str(err.value).startswith(f"path '{path}':") and words in str(err.value), str(err.value)


def test_approach_outputs_are_refused_where_the_case_has_no_such_phase():
    """A sweep's output and a fit's evidence of a vehicle without an approach, or of a phase beyond its last, are
    refused saying so (as a rest position of a case without a road); an approach's result is no input to vary."""
    case = case_from_dict(_with(_approach()))
    assert without_approach(case, "vehicles[0].approach[2].position[1]") is None
    check_sweep(case, {"vehicles[0].speed": [8.0, 10.0]}, outputs=["vehicles[0].approach[2].speed",
                                                                   "vehicles[0].approach[0].position[1]"])
    assert evidence_kind(case, "vehicles[0].approach[0].yaw") == (True, 360.0)
    assert evidence_kind(case, "vehicles[0].approach[1].time") == (True, 0.0)
    refused = {"vehicles[1].approach[0].speed": "vehicles[1] has no approach: give it one, e.g. \"approach\": ",
               "vehicles[0].approach[3].time": "vehicles[0]'s approach has 3 phases (approach[0] to approach[2], "
                                               "earliest first)"}
    for path, words in refused.items():
        assert without_approach(case, path).startswith(f"{path}: {words}")
        with pytest.raises(CaseError) as err:
            check_sweep(case, {"vehicles[0].speed": [8.0, 10.0]}, outputs=[path])
        assert str(err.value).startswith(f"output {path}: ") and words in str(err.value), str(err.value)
        with pytest.raises(CaseError) as err:
            evidence_kind(case, path)
        assert str(err.value).startswith(f"case '{NAME}': evidence: {path}: ") and words in str(err.value)
    with pytest.raises(CaseError, match=r"unknowns: path 'vehicles\[0\]\.approach\[0\]\.speed': a result of "
                                        r"vehicles\[0\]'s approach .*not an input"):
        unknown_path(case, "vehicles[0].approach[0].speed")
    plain = case_from_dict(SPIN_OUT)  # no approach at all; not even a road
    assert "vehicles[0] has no approach" in without_approach(plain, "vehicles[0].approach[0].speed")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CaseWarning)  # its vehicles' wheels and its interaction, without a road
        no_road = case_from_dict(_with(lambda d: d.pop("road")))
    assert "vehicles[0] has no approach" in without_approach(no_road, "vehicles[0].approach[0].speed")
    # a batch checks a path once per key: the approach's phases are part of it
    assert path_key(plain) != path_key(case)
    assert path_key(case) != path_key(case_from_dict(_with(_approach(PHASES[:2]))))


def test_get_output_reads_the_approach_from_a_result():
    """``get_output`` reads phase k of ``result.approach[i]`` (batched or not); a result without the vehicle's
    approach, or without the phase, is refused."""
    rows, phases = 3, 2
    k = np.arange(rows * phases, dtype=float).reshape(rows, phases)
    found = ApproachResult(speed=10 + k, time=-k, position=np.stack([k, -k], -1), yaw=5 * k, distance=2 * k,
                           velocity=np.zeros((rows, phases, 2)), yaw_rate=np.zeros((rows, phases)))
    result = ExchangeResult(None, (), approach=(found, None), interactions=None)  # only what the paths read
    np.testing.assert_array_equal(get_output(result, "vehicles[0].approach[1].speed"), 10 + k[:, 1])
    np.testing.assert_array_equal(get_output(result, "vehicles[0].approach[0].time"), -k[:, 0])
    np.testing.assert_array_equal(get_output(result, "vehicles[0].approach[1].position[1]"), -k[:, 1])
    np.testing.assert_array_equal(get_output(result, "vehicles[0].approach[1].yaw"), 5 * k[:, 1])
    np.testing.assert_array_equal(get_output(result, "vehicles[0].approach[0].distance"), 2 * k[:, 0])
    one = ExchangeResult(None, (), approach=(ApproachResult(*(x[2] for x in found[:7])), None), interactions=None)
    assert float(get_output(one, "vehicles[0].approach[1].position[0]")) == k[2, 1]
    for path, words in [("vehicles[1].approach[0].speed", "vehicles[1] has no approach"),
                        ("vehicles[0].approach[2].speed", "vehicles[0]'s approach has 2 phases"),
                        ("vehicles[5].approach[0].speed", "vehicles[5] has no approach")]:
        with pytest.raises(PathError, match=re.escape(f"path '{path}': {words}")):
            get_output(result, path)
    with pytest.raises(PathError, match="vehicles\\[0\\] has no approach"):
        get_output(ExchangeResult(None, (), approach=None, interactions=None), "vehicles[0].approach[0].speed")


V, D, YAW = 20 * U.MPH, 12.0, 30.0  # the impact speed, the skid's length (m), the heading (deg)
HEADING = np.array([math.cos(math.radians(YAW)), math.sin(math.radians(YAW))])
CAR = {"mass": 1500, "inertia": [500, 2400, 2600], "length": 4.5, "width": 1.8, "height": 1.5, "cg_to_front": 2.2,
       "cg_height": 0.55, "wheelbase": 2.7, "track": 1.5, "cg_to_front_axle": 1.2, "yaw": YAW,
       "after": {"wheels": "locked"}}
REAR_END = {"name": "skid into a rear-end",
            "vehicles": [{**CAR, "name": "Striking", "position": [0, 0], "speed": V,
                          "approach": [{"wheels": "locked", "distance": D}]},
                         {**CAR, "name": "Struck", "position": list(4.4 * HEADING), "speed": 5 * U.MPH}],
            "contact": {"point": [*(2.15 * HEADING), 0.55], "normal": YAW + 180, "restitution": 0.1, "friction": 0.5},
            "road": {"friction": 0.7}}


@pytest.mark.slow
def test_a_locked_skid_before_the_impact_meets_its_closed_form_through_solve_json(tmp_path, capsys):
    """``ks-jax solve --json``: a car that skids D m with its four wheels locked, straight (no yaw rate), into the rear
    of another at V started its skid at sqrt(V^2 + 2 mu g D), (v_start - V) / (mu g) before the impact, D behind
    its place at the impact along its heading, heading as there; the struck car has no approach. The panel shows
    the approach."""
    path = tmp_path / "skid.json"
    path.write_text(json.dumps(REAR_END))
    code, text, err = run_cli(capsys, "solve", str(path), "--json")
    assert code == 0, err
    (out,) = json.loads(text)["cases"]
    striking, struck = out["vehicles"]
    assert "approach" not in struck
    (phase,) = striking["approach"]
    assert set(phase) == {"speed", "time", "position", "yaw", "distance"}
    mu_g = 0.7 * U.G0
    start = math.sqrt(V**2 + 2 * mu_g * D)
    np.testing.assert_allclose(phase["speed"], start, rtol=1e-5)
    np.testing.assert_allclose(phase["time"], -(start - V) / mu_g, rtol=0, atol=1e-5)
    np.testing.assert_allclose(phase["distance"], D, rtol=1e-6)
    np.testing.assert_allclose(phase["position"], -D * HEADING, rtol=0, atol=1e-5)
    np.testing.assert_allclose(phase["yaw"], YAW, rtol=0, atol=1e-6)
    code, text, err = run_cli(capsys, "solve", str(path))
    assert code == 0, err
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if "approach (each phase's start)" in line)
    assert "time, speed, distance to the impact" in lines[at]
    row = lines[at + 1]
    assert row.strip().startswith("approach[0]") and f"{-(start - V) / mu_g:.3f} s" in row, row
    assert f"{start:.3f} m/s" in row and f"{start / U.MPH:.2f} mph" in row and f"{D:.3f} m" in row, row
    assert sum("approach (each phase's start)" in line for line in lines) == 1  # the struck car has none
