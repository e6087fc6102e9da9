"""Case files (``ks_jax.case``): units at the edge, every class of bad input refused with the case, the field,
the value and the rule, a bad case in a file costing only that case, and the paths of single inputs and
results."""

import contextlib
import copy
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax.case import CaseError, CaseWarning, at_rest_after, case_from_dict, defined_output
from samples import CASES, SEED0, US_CASE, run_cli, si_twin


@pytest.mark.slow
def test_unit_strings_equal_si_numbers():
    a = ks_jax.solve(case_from_dict(US_CASE)).to_dict()
    b = ks_jax.solve(case_from_dict(si_twin())).to_dict()
    assert a["contact"]["status"] == "ok"
    np.testing.assert_allclose(a["contact"]["impulse"], b["contact"]["impulse"], rtol=1e-12)
    for va, vb in zip(a["vehicles"], b["vehicles"]):
        np.testing.assert_allclose(va["velocity_after"], vb["velocity_after"], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(va["angular_velocity_after"], vb["angular_velocity_after"], rtol=1e-12, atol=1e-12)


def _bad(mutate):
    d = copy.deepcopy(US_CASE)
    mutate(d)
    return d


BAD = {
    "mass <= 0": (lambda d: d["vehicles"][0].update(weight="-1200 lbf"),
                  r"vehicles\[0\]\.weight = '-1200 lbf'.*positive"),
    "zero mass": (lambda d: d["vehicles"][1].update(mass=0), r"vehicles\[1\]\.mass = 0: mass must be positive"),
    "inertia <= 0": (lambda d: d["vehicles"][0].update(inertia=[400, -5, 2000]),
                     r"vehicles\[0\]\.inertia\[1\].*positive"),
    "inertia tensor not PD": (lambda d: d["vehicles"][1].update(inertia=[[1, 2, 0], [2, 1, 0], [0, 0, 1]]),
                              r"vehicles\[1\]\.inertia.*positive definite"),
    "restitution": (lambda d: d["contact"].update(restitution=1.5), r"contact\.restitution = 1\.5.*\[-1, 1\]"),
    "friction": (lambda d: d["contact"].update(friction=-0.1), r"contact\.friction = -0\.1.*>= 0"),
    "nan": (lambda d: d["vehicles"][1].update(speed=float("nan")), r"vehicles\[1\]\.speed = nan.*finite"),
    "inf": (lambda d: d["vehicles"][0]["position"].__setitem__(0, float("inf")),
            r"vehicles\[0\]\.position\[0\].*finite"),
    "wrong dimension": (lambda d: d["vehicles"][0].update(length="3 kg"), r"vehicles\[0\]\.length = '3 kg'.*dimension"),
    "unknown unit": (lambda d: d["vehicles"][1].update(speed="30 zorks"),
                     r"vehicles\[1\]\.speed = '30 zorks'.*unknown unit"),
    "missing field": (lambda d: d["vehicles"][0].pop("width"), r"vehicles\[0\]\.width: missing field"),
    "missing restitution": (lambda d: d["contact"].pop("restitution"), r"contact\.restitution: missing field"),
    "one vehicle": (lambda d: d["vehicles"].pop(), r"1 given and no fixed object; a case needs two bodies"),
    "three vehicles without a road": (lambda d: d["vehicles"].append(copy.deepcopy(d["vehicles"][0])),
                                      r"road: missing field; a case of more than two bodies needs a road"),
    "nine vehicles": (lambda d: d["vehicles"].extend([copy.deepcopy(d["vehicles"][0])] * 7),
                      r"vehicles: 9 given; a case has 1 to 8 vehicles"),
    "zero normal": (lambda d: d["contact"].update(normal=[0, 0, 0]), r"contact\.normal.*non-zero"),
    "misspelt required field": (lambda d: d["vehicles"][1].update(sped=d["vehicles"][1].pop("speed")),
                                r"vehicles\[1\]\.speed: missing field"),
}


# inputs of BAD that also warn: a misspelt field is reported as unknown, the warning that points at the typo
WARNS = {"misspelt required field": r"vehicles\[1\]\.sped: unknown field"}


@pytest.mark.parametrize("label", list(BAD))
def test_bad_input_is_refused_with_field_value_and_rule(label, tmp_path, capsys):
    mutate, pattern = BAD[label]
    d = _bad(mutate)
    warns = pytest.warns(CaseWarning, match=WARNS[label]) if label in WARNS else contextlib.nullcontext()
    with warns, pytest.raises(CaseError, match=pattern) as err:
        case_from_dict(d)
    assert "case 'units check'" in str(err.value)
    # the CLI: one line on stderr, no traceback, exit status 2
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(d))
    code, out, errtext = run_cli(capsys, "solve", str(path), "--json")
    assert code == 2 and out == ""
    # one error line (after any warning about an ignored field, which points at a typo), no traceback
    assert errtext.splitlines()[-1].startswith("ks-jax: error: case 'units check'") and "Traceback" not in errtext


@pytest.mark.slow
def test_bad_case_in_a_batch_is_reported_and_the_others_solved(tmp_path, capsys):
    good = copy.deepcopy(US_CASE)
    bad = _bad(BAD["restitution"][0])
    bad["name"] = "bad one"
    other = copy.deepcopy(US_CASE)
    other["name"] = "second good"
    other["vehicles"][1]["speed"] = "40 mph"
    path = tmp_path / "many.json"
    path.write_text(json.dumps({"cases": [good, bad, other]}))
    code, out, err = run_cli(capsys, "solve", str(path), "--json")
    assert code == 1  # solved what could be, and says (exit status) that a case was not
    res = json.loads(out)["cases"]
    assert [r["contact"]["status"] for r in res][0] == "ok"
    assert res[1]["contact"]["status"].startswith("invalid: ") and "restitution" in res[1]["contact"]["status"]
    assert res[2]["contact"]["status"] == "ok"
    # the good cases equal their single solves
    for r, d in ((res[0], good), (res[2], other)):
        single = ks_jax.solve(case_from_dict(d)).to_dict()
        np.testing.assert_allclose(r["contact"]["impulse"], single["contact"]["impulse"], rtol=1e-12)
    assert "bad one" in err


def test_toml_case_and_unreadable_file(tmp_path, capsys):
    path = tmp_path / "c.toml"
    path.write_text('name = "t"\n[[vehicles]]\nmass = 1000\n')
    code, _, err = run_cli(capsys, "solve", str(path))
    assert code == 2 and "a case needs two bodies" in err
    path = tmp_path / "broken.json"
    path.write_text("{not json")
    code, _, err = run_cli(capsys, "solve", str(path))
    assert code == 2 and "cannot be read" in err
    code, _, err = run_cli(capsys, "solve", str(tmp_path / "missing.json"))
    assert code == 2 and "no such file" in err


@pytest.mark.slow
def test_paths_refuse_unknown_names():
    case = case_from_dict(US_CASE)
    with pytest.raises(CaseError, match="not a vehicle input"):
        ks_jax.get_input(case.inputs, "vehicles[0].sped")
    with pytest.raises(CaseError, match="not a contact result"):
        ks_jax.get_output(ks_jax.solve(case).result, "contact.impulse_size")
    new = ks_jax.set_input(case.inputs, "vehicles[1].yaw_rate", 0.5)
    assert float(ks_jax.get_input(new, "vehicles[1].angular_velocity[2]")) == 0.5
    for path in ("vehicles[1].inertia[3]", "contact.point[3]"):
        with pytest.raises(CaseError, match=r"index out of range \(0..2\)"):
            ks_jax.get_input(case.inputs, path)
    with pytest.raises(CaseError, match=r"index out of range \(0..2\)"):
        ks_jax.get_output(ks_jax.solve(case).result, "vehicles[0].delta_v[5]")
    with pytest.raises(CaseError, match=r"the status is a code.*read result.contact.status"):
        ks_jax.get_output(ks_jax.solve(case).result, "contact.status")
    for value in ("20 mph", None, [1.0, 2.0]):
        with pytest.raises(CaseError, match="the value must be one number, in SI units"):
            ks_jax.set_input(case.inputs, "vehicles[1].speed", value)


NO_ROAD_WORDS = "the case has no road, so no motion to rest: give it one"


@pytest.mark.parametrize("road, path, words", [
    # inputs (get_input, set_input, a sweep's --over, a fit's unknowns read them so)
    (True, "exchanges[0].time", "a result, not an input"),
    (True, "interaction.foo", "the later exchanges' inputs are interaction.restitution, interaction.friction, "
                              "interaction.penetration_time"),
    (True, "vehicles[0].brake[4]", "'brake' holds four wheels' fractions: name one, brake[0] .. brake[3]"),
    (True, "vehicles[0].brake", "'brake' holds four wheels' fractions"),
    (True, "vehicles[0].approach[0].speed", "a result of vehicles[0]'s approach"),
    (True, "road.grade", "the road's one input is road.friction"),
    (True, "vehicles[0].weight", "a case's weight sets its mass: use vehicles[0].mass, in lb where weights are in lbf"),
    (True, "vehicles[0].velocity", "(vary speed and course instead)"),
    (False, "road.friction", NO_ROAD_WORDS),
    (False, "interaction.restitution", NO_ROAD_WORDS),
    # outputs (get_output, a sweep's outputs, a fit's evidence check them so)
    (None, "vehicles[99].speed", "vehicle index must be 0 to 7 (a case has at most 8 vehicles)"),
    (None, "road.friction", "road.friction is an input, not a result"),
    (None, "vehicles[0].speed@1.0.x", "the time after '@' (1.0.x): '1.0.x' is not a '<number> <unit>' quantity"),
    (None, "vehicles[0].speed@1e9 s", "the time after '@' must be finite, within +/-3600 s of the impact"),
    (None, "vehicles[0].position@1 s", "'position' is a vector: name a component, e.g. vehicles[0].position[0]@1"),
    (None, "vehicles[0].position[5]@1 s", "index out of range (0..1)"),
    (None, "vehicles[0].speed[0]@1 s", "'speed' is a number and takes no index"),
])
def test_a_path_that_breaks_a_rule_is_refused_naming_the_path_and_the_rule(road, path, words):
    """road: an input path read from a case with a road (True) or without (False); None: an output path checked."""
    with pytest.raises(ks_jax.case.PathError) as err:
        if road is None:
            ks_jax.case.check_output_path(path)
        else:
            ks_jax.get_input(ks_jax.load_case(CASES / "rest_seed_000.json" if road else SEED0).inputs, path)
    assert str(err.value).startswith(f"path '{path}': ") and words in str(err.value)


def test_unknown_field_is_ignored_with_a_warning_naming_it(tmp_path, capsys):
    d = _bad(lambda d: d["vehicles"][1].update(year=2021))
    with pytest.warns(ks_jax.case.CaseWarning, match=r"case 'units check': vehicles\[1\]\.year: unknown field"):
        case = case_from_dict(d)
    # the case is solved as without the field
    a = ks_jax.solve(case).to_dict()
    b = ks_jax.solve(case_from_dict(US_CASE)).to_dict()
    assert a["contact"]["impulse"] == b["contact"]["impulse"]
    path = tmp_path / "extra.json"
    path.write_text(json.dumps(d))
    code, out, err = run_cli(capsys, "solve", str(path), "--json")
    assert code == 0 and json.loads(out)["cases"][0]["contact"]["status"] == "ok"
    assert "ks-jax: warning: case 'units check': vehicles[1].year: unknown field, ignored" in err


def test_a_bad_reference_costs_its_case_only(tmp_path, capsys):
    """``reference`` (reported values printed beside ks-jax's) is read with its case: a bad entry makes that
    case invalid, naming it, and the other cases are solved and printed, with or without --json."""
    good = copy.deepcopy(US_CASE)
    good["reference"] = {"contact.impulse_magnitude": "1000 lbf*s", "vehicles[0].pdof": 359}
    bads = [{"vehicles[0].bogus": 5}, [1, 2], {"contact.impulse_magnitude": "5,946.847 N*s"},
            {"contact.status": "ok"}]
    cases = [good] + [dict(copy.deepcopy(US_CASE), name=f"bad {k}", reference=ref) for k, ref in enumerate(bads)]
    path = tmp_path / "refs.json"
    path.write_text(json.dumps({"cases": cases}))
    for flags in ((), ("--json",)):
        code, out, err = run_cli(capsys, "solve", str(path), *flags)
        assert code == 1 and "Traceback" not in err
        for k in range(len(bads)):
            line = next(t for t in err.splitlines() if f"'bad {k}'" in t)
            assert "invalid: case" in line and "reference" in line, line
    res = json.loads(run_cli(capsys, "solve", str(path), "--json")[1])["cases"]
    assert res[0]["contact"]["status"] == "ok" and all(r["contact"]["status"].startswith("invalid") for r in res[1:])
    out = run_cli(capsys, "solve", str(path))[1]
    # a PDOF is compared on the circle: the hand value, in degrees, from the JSON
    pdof = res[0]["vehicles"][0]["pdof"]
    assert f"{(pdof - 359 + 180) % 360 - 180:+.4f} deg" in out.split("vehicles[0].pdof")[1].splitlines()[0]


def test_undefined_outputs_are_masked_alike_on_numpy_and_on_jax_results():
    """``defined_output`` and ``at_rest_after`` compute with NumPy on a solved case's NumPy results (a report
    compiles no XLA program for them) and with jax.numpy on JAX arrays (a sweep's traced rows): the same
    numbers and NaN in the same places, for a case that exchanges an impulse and for one at rest (no
    approach: the impulse's directions and both courses after are undefined)."""
    still = copy.deepcopy(US_CASE)
    still["vehicles"][1].update(speed="0 mph", yaw_rate=0)
    undefined = []
    for d in (US_CASE, still):
        result = ks_jax.solve(case_from_dict(d)).result
        as_jax = jax.tree_util.tree_map(jnp.asarray, result)
        paths = [f"contact.{name}" for name in result.contact._fields] + [
            f"vehicles[{k}].{name}" for k in (0, 1) for name in result.vehicles[k]._fields]
        for path in paths:
            got, ref = defined_output(result, path), defined_output(as_jax, path)
            assert isinstance(got, (np.ndarray, np.generic)) and isinstance(ref, jax.Array), path
            np.testing.assert_array_equal(got, np.asarray(ref), err_msg=path)
        for k in (0, 1):
            assert isinstance(at_rest_after(result.vehicles[k]), (np.ndarray, np.generic))
            assert bool(at_rest_after(result.vehicles[k])) == bool(at_rest_after(as_jax.vehicles[k]))
        undefined.append({p for p in paths if np.isnan(np.asarray(defined_output(result, p), float)).any()})
    assert not undefined[0]
    assert {"vehicles[0].pdof", "vehicles[1].course_after", "contact.impulse_azimuth"} <= undefined[1]


@pytest.mark.parametrize("field, value, message", [
    # the values by hand from 1 ft = 0.3048 m and 1 lb = 0.45359237 kg: 20 ft = 6.096 m, 15 ft = 4.572 m,
    # 5 ft = 1.524 m, 4.5 ft = 1.3716 m, 16 ft = 4.8768 m, 6 ft = 1.8288 m, 1e-9 lb = 4.536e-10 kg
    ("cg_to_front", "20 ft", "vehicles[0].cg_to_front = '20 ft' (6.096 m): must be between 0 and the length "
                             "(15 ft, 4.572 m)"),
    ("cg_to_front", 20, "vehicles[0].cg_to_front = 20: must be between 0 and the length (15 ft, 4.572 m)"),
    ("cg_height", "5 ft", "vehicles[0].cg_height = '5 ft' (1.524 m): must be between 0 and the height "
                          "(4.5 ft, 1.372 m)"),
    ("wheelbase", "16 ft", "vehicles[0].wheelbase = '16 ft' (4.877 m): must be positive and at most the length "
                           "(15 ft, 4.572 m)"),
    ("track", "7 ft", "vehicles[0].track = '7 ft' (2.134 m): must be positive and at most the width (6 ft, 1.829 m)"),
    ("mass", "1e-9 lb", "vehicles[0].mass = '1e-9 lb' (4.536e-10 kg): must be at least 0.001 kg"),
])
def test_range_errors_give_the_value_as_typed_and_in_si(field, value, message):
    """A value typed in US units that breaks a rule set by another input is shown as typed and in SI, and the
    limit in the unit its own input was typed in and in SI, so that the two can be compared at a glance."""
    d = copy.deepcopy(US_CASE)
    if field in ("wheelbase", "track"):
        d["road"] = {"friction": 0.7}
    if field == "mass":
        d["vehicles"][0].pop("weight")
    d["vehicles"][0][field] = value
    with pytest.raises(CaseError) as err:
        case_from_dict(d)
    assert str(err.value).startswith(f"case 'units check': {message}"), str(err.value)
    si = copy.deepcopy(d)  # the same case with the length in bare metres: its limit in SI alone
    si["vehicles"][0]["length"] = 15 * 0.3048
    if field == "cg_to_front":
        with pytest.raises(CaseError, match=r"must be between 0 and the length \(4\.572 m\)$"):
            case_from_dict(si)
