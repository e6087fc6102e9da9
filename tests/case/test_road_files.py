"""Case files with a road (docs/model.md, "Motion to rest"): defaults, units, and a clear error for every bad
value, naming the case, the field, the value and the rule."""

import copy
import json
import math
import warnings

import numpy as np
import pytest

from ks_jax import units as U
from ks_jax.case import CaseError, CaseWarning, case_from_dict, cases_from_data
from samples import CASES

SPIN_OUT = json.loads((CASES / "tbone_spin_out.json").read_text())


def _with(change):
    d = copy.deepcopy(SPIN_OUT)
    change(d)
    return d


def test_a_road_reads_its_units_and_defaults():
    """Given values in feet and degrees reach the inputs in SI; where the file gives none, the wheelbase is 0.6 of
    the length, the track 0.85 of the width, the axles set in equally from the ends, the wheels free with a
    rolling resistance of 0.015, the step 5 ms and the limit 20 s."""
    def change(d):
        d["vehicles"][1] = {k: v for k, v in d["vehicles"][1].items()
                            if k not in ("wheelbase", "track", "cg_to_front_axle", "after")}
        d["vehicles"][0]["after"] = {"wheels": [0.5, 0.5, 0, 0.25], "steer": "-4 deg", "rolling_resistance": 0.02}
    case = case_from_dict(_with(change))
    a0, a1 = case.inputs.road.vehicles
    np.testing.assert_allclose([a0.wheelbase, a0.track, a0.cg_to_front_axle], np.array([9.2, 5.2, 3.9]) * U.FT)
    np.testing.assert_allclose(a0.brake, [0.5, 0.5, 0, 0.25])
    np.testing.assert_allclose([a0.steer, a0.rolling_resistance], [math.radians(-4), 0.02])
    length, width, cg_to_front = 19 * U.FT, 6.7 * U.FT, 8 * U.FT
    np.testing.assert_allclose([a1.wheelbase, a1.track], [0.6 * length, 0.85 * width])
    np.testing.assert_allclose(a1.cg_to_front_axle, cg_to_front - 0.2 * length)
    np.testing.assert_allclose(a1.brake, [0, 0, 0, 0])
    assert a1.rolling_resistance == 0.015 and float(case.inputs.road.friction) == 0.75
    assert (case.motion.time_step, case.motion.time_limit) == (0.005, 20.0)


@pytest.mark.parametrize("change, field, rule", [
    (lambda d: d["road"].update(friction=-0.2), "road.friction", "must be >= 0"),
    (lambda d: d["road"].update(friction=1e300), "road.friction", "at most 10"),
    (lambda d: d["road"].pop("friction"), "road.friction", "missing field"),
    (lambda d: d["road"].update(time_step="0 s"), "road.time_step", "(0, 0.05] s"),
    (lambda d: d["road"].update(time_limit="2 h"), "road.time_limit", "(0, 600] s"),
    (lambda d: d["road"].update(time_step="0.0001 s", time_limit="600 s"), "road", "more than"),
    (lambda d: d["vehicles"][0]["after"].update(wheels=[0.5, 1.2, 0, 0]), "vehicles[0].after.wheels[1]",
     "a brake fraction must be in [0, 1]"),
    (lambda d: d["vehicles"][0]["after"].update(wheels="skidding"), "vehicles[0].after.wheels",
     "\"free\", \"locked\" or four brake fractions"),
    (lambda d: d["vehicles"][0]["after"].update(wheels=[0, 0, 0]), "vehicles[0].after.wheels",
     "four brake fractions"),
    (lambda d: d["vehicles"][0].update(wheelbase="16 ft"), "vehicles[0].wheelbase", "at most the length"),
    (lambda d: d["vehicles"][0].update(wheelbase="-9 ft"), "vehicles[0].wheelbase", "must be positive"),
    (lambda d: d["vehicles"][1].update(track="7 ft"), "vehicles[1].track", "at most the width"),
    (lambda d: d["vehicles"][1].update(cg_to_front_axle="12.5 ft"), "vehicles[1].cg_to_front_axle",
     "the CG must lie between the axles"),
    (lambda d: d["vehicles"][1].update(cg_to_front_axle="9 ft", wheelbase="10 ft"), "vehicles[1].cg_to_front_axle",
     "within the vehicle's length"),
    (lambda d: d["vehicles"][0]["after"].update(steer="75 deg"), "vehicles[0].after.steer", "within +-60 deg"),
    (lambda d: d["vehicles"][0]["after"].update(rolling_resistance=0.9), "vehicles[0].after.rolling_resistance",
     "below the road's friction"),
    (lambda d: d["vehicles"][0]["after"].update(rolling_resistance="fast"), "vehicles[0].after.rolling_resistance",
     "fast"),
])
def test_a_bad_road_value_is_refused_naming_the_case_field_value_and_rule(change, field, rule):
    with pytest.raises(CaseError) as err:
        case_from_dict(_with(change))
    text = str(err.value)
    assert text.startswith(f"case '{SPIN_OUT['name']}': {field}") and rule in text, text


def test_a_bad_road_costs_its_case_only_and_motion_fields_without_a_road_are_named():
    """In a file of cases a bad road is reported in its case, the others are read; wheels given to a case without a
    road are ignored with a warning that says how to add one."""
    bad = _with(lambda d: d["road"].update(friction="slippery"))
    cases = cases_from_data({"cases": [bad, SPIN_OUT]})
    assert not cases[0].valid and "road.friction" in cases[0].error and cases[1].valid
    no_road = _with(lambda d: d.pop("road"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        case = case_from_dict(no_road)
    assert case.motion is None and case.inputs.road is None
    said = [str(w.message) for w in caught if issubclass(w.category, CaseWarning)]
    assert any("vehicles[0]: wheelbase, track, cg_to_front_axle, after" in s and "\"road\"" in s for s in said), said
