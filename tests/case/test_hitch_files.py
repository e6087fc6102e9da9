"""Articulated vehicles in case files (docs/model.md, "Articulated vehicles: the case file"): a towed vehicle's
``hitch`` read in SI, its position and velocity followed from its tow's (a hand calculation), every rule refused
with the case, the field, the value and the rule, ``follow_tows`` against the hand calculation and its derivatives
against finite differences, and the paths a hitch sets refused to sweeps, fits and ``set_input``. Loading and small
eager computations only: no solve."""

import copy
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fit.spec import evidence_kind, unknown_path
from ks_jax import units as U
from ks_jax.case import CaseError, CaseWarning, PathError, as_arrays, case_from_dict, cases_from_data, follow_tows
from ks_jax.case import follows_tow, get_input, input_ties, load_cases, path_key, set_input
from ks_jax.sweeps.engine import check as check_sweep

TRACTOR = {"name": "Tractor", "mass": 8000, "inertia": [5000, 30000, 30000], "length": 6.0, "width": 2.5,
           "height": 3.5, "cg_to_front": 2.5, "cg_height": 1.0, "wheelbase": 3.8, "track": 2.0,
           "cg_to_front_axle": 1.5, "position": [0, 0], "yaw": 0, "speed": 10, "yaw_rate": 5}
# a semi-trailer turned 30 deg to its tractor, turning at 3 deg/s: its kingpin 5.3 m ahead of its CG, on the fifth
# wheel 1.9 m behind the tractor's CG; its axle group 5 m behind its CG (cg_to_front_axle - wheelbase)
TRAILER = {"name": "Semi-trailer", "mass": 20000, "inertia": [20000, 300000, 300000], "length": 13.6, "width": 2.5,
           "height": 4.0, "cg_to_front": 6.5, "cg_height": 1.5, "wheelbase": 10.3, "track": 2.0,
           "cg_to_front_axle": 5.3, "yaw": 30, "yaw_rate": 3,
           "hitch": {"to": 0, "point": [5.3, 0], "point_on_tow": [-1.9, 0], "max_angle": "40 deg",
                     "kind": "fifth_wheel"}}
CAR = {"name": "Car", "mass": 1500, "inertia": [500, 2400, 2600], "length": 4.6, "width": 1.8, "height": 1.5,
       "cg_to_front": 2.0, "cg_height": 0.55, "position": [-8, -9], "yaw": 90, "speed": 15}
SEMI = {"name": "semi", "vehicles": [TRACTOR, TRAILER, CAR], "between": [2, 1],
        "contact": {"point": [-8, -5, 0.8], "normal": 90, "restitution": 0.1, "friction": 0.5},
        "road": {"friction": 0.7}}

# By hand: the tractor at the origin heading +x at 10 m/s, turning at 5 deg/s; its fifth wheel at (-1.9, 0). The
# trailer's kingpin from its CG, turned 30 deg: (5.3 cos 30, 5.3 sin 30) = (4.5899, 2.65). Its CG: the fifth wheel
# less that. Its velocity: the fifth wheel's, (10, 0) + w0 k x (-1.9, 0) = (10, -1.9 w0), less w1 k x (4.5899, 2.65)
# = w1 (-2.65, 4.5899).
COS30 = math.sqrt(3) / 2
W0, W1 = math.radians(5), math.radians(3)
POSITION = np.array([-1.9 - 5.3 * COS30, -2.65])
VELOCITY = np.array([10 + 2.65 * W1, -1.9 * W0 - 5.3 * COS30 * W1])


def _with(change, base=SEMI):
    d = copy.deepcopy(base)
    change(d)
    return d


def test_a_semi_trailer_follows_its_tractor():
    """The trailer's position and velocity, left out of the file, are those the hitch gives it (the hand
    calculation), its z its cg_height; the hitch reaches CaseInputs in SI and Motion.links with its kind."""
    case = case_from_dict(SEMI)
    assert case.motion.links == ((1, 0, "fifth_wheel"),)
    (h,) = case.inputs.hitches
    np.testing.assert_allclose(h.point, [5.3, 0.0])
    np.testing.assert_allclose(h.point_on_tow, [-1.9, 0.0])
    np.testing.assert_allclose(h.max_angle, math.radians(40))
    v = case.inputs.vehicles[1]
    np.testing.assert_allclose(v.position, [*POSITION, 1.5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(v.speed, math.hypot(*VELOCITY), rtol=1e-12)
    np.testing.assert_allclose(v.course, math.atan2(VELOCITY[1], VELOCITY[0]), rtol=1e-12)
    np.testing.assert_allclose(v.angular_velocity, [0, 0, W1], rtol=1e-12)
    assert float(v.velocity_z) == 0.0
    tractor = case.inputs.vehicles[0]  # the tow is as the file gives it
    np.testing.assert_allclose([*tractor.position, tractor.speed, tractor.course], [0, 0, 1.0, 10, 0])


def test_a_hitch_in_units_and_defaults():
    """Points in feet, an angle in rad; without kind a drawbar, without max_angle no limit (inf)."""
    def change(d):
        d["vehicles"][1]["hitch"] = {"to": 0, "point": [f"{5.3 / U.FT!r} ft", "0 ft"], "point_on_tow": [-1.9, "0 in"],
                                     "max_angle": "0.7 rad"}
    case = case_from_dict(_with(change))
    assert case.motion.links == ((1, 0, "drawbar"),)
    np.testing.assert_allclose(case.inputs.hitches[0].point, [5.3, 0.0], rtol=1e-12)
    np.testing.assert_allclose(case.inputs.hitches[0].max_angle, 0.7)
    np.testing.assert_allclose(case.inputs.vehicles[1].position[:2], POSITION, rtol=0, atol=1e-12)
    case = case_from_dict(_with(lambda d: d["vehicles"][1]["hitch"].pop("max_angle")))
    assert math.isinf(case.inputs.hitches[0].max_angle)


def test_given_position_and_velocity_within_the_tolerance_are_taken_as_followed():
    """A file may give the towed vehicle's position and velocity: within 0.05 m and 0.05 m/s of what follows they
    are accepted, and the inputs hold the followed values; a 3-D position keeps its own z."""
    for given in ({"position": [*(POSITION + [0.03, -0.02]), 1.7], "velocity": list(VELOCITY + [0.02, 0.03])},
                  {"position": list(POSITION), "speed": math.hypot(*VELOCITY) + 0.04},
                  {"speed": math.hypot(*VELOCITY), "course": math.degrees(math.atan2(VELOCITY[1], VELOCITY[0]))}):
        case = case_from_dict(_with(lambda d: d["vehicles"][1].update(given)))
        v = case.inputs.vehicles[1]
        np.testing.assert_allclose(v.position[:2], POSITION, rtol=0, atol=1e-12)
        np.testing.assert_allclose(v.position[2], 1.7 if len(given.get("position", ())) == 3 else 1.5)
        np.testing.assert_allclose(v.speed * np.array([math.cos(v.course), math.sin(v.course)]), VELOCITY,
                                   rtol=0, atol=1e-12)


def test_a_chain_is_followed_tow_first():
    """A tractor (0) towing a dolly-less full trailer (2) that tows another (1), listed in the file trailer first:
    the links put the tractor's link first, and the last trailer follows the one before it."""
    first = {**copy.deepcopy(TRAILER), "name": "Trailer A", "yaw": 0, "yaw_rate": 0,
             "hitch": {"to": 0, "point": [6.0, 0], "point_on_tow": [-3.0, 0]}}
    second = {**copy.deepcopy(TRAILER), "name": "Trailer B", "yaw": 0, "yaw_rate": 0,
              "hitch": {"to": 2, "point": [6.5, 0], "point_on_tow": [-7.0, 0]}}
    tractor = {**TRACTOR, "yaw_rate": 0}
    car = {**CAR, "position": [-30, -9]}
    d = {**copy.deepcopy(SEMI), "vehicles": [tractor, second, first, car], "between": [3, 1]}
    case = case_from_dict(d)
    assert case.motion.links == ((2, 0, "drawbar"), (1, 2, "drawbar"))
    np.testing.assert_allclose(case.inputs.vehicles[2].position[:2], [-9.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(case.inputs.vehicles[1].position[:2], [-22.5, 0.0], atol=1e-12)
    np.testing.assert_allclose([case.inputs.vehicles[k].speed for k in (1, 2)], [10.0, 10.0])


def _raise(change, base=SEMI):
    with pytest.raises(CaseError) as err:
        case_from_dict(_with(change, base))
    return str(err.value)


def _hitch(**kw):
    return lambda d: d["vehicles"][1]["hitch"].update(kw)


BAD = {
    "tows itself": (_hitch(to=1), r"vehicles[1].hitch.to = 1: a vehicle cannot tow itself"),
    "no such vehicle": (_hitch(to=7), "vehicles[1].hitch.to = 7: must be the index of another vehicle of the case"),
    "a fixed object": (_hitch(to="fixed[0]"), "vehicles[1].hitch.to = 'fixed[0]': must be the index of another "
                                              "vehicle"),
    "not an index": (_hitch(to=0.0), "vehicles[1].hitch.to = 0.0: must be the index"),
    "no tow": (lambda d: d["vehicles"][1]["hitch"].pop("to"), "vehicles[1].hitch.to: missing field"),
    "towed twice": (lambda d: d["vehicles"][1].update(hitch=[TRAILER["hitch"], {**TRAILER["hitch"], "to": 2}]),
                    "vehicles[1].hitch = [{'to': 0"),
    "a loop": (lambda d: d["vehicles"][0].update(hitch={"to": 1, "point": [3, 0], "point_on_tow": [-6, 0]}),
               "vehicles[0].hitch.to = 1: the hitches make a loop (vehicles[0], towed by vehicles[1], towed by "
               "vehicles[0])"),
    "no road": (lambda d: d.pop("road"), "road: missing field; a case with a hitch (vehicles[1].hitch) needs a road: "
                                         "the joint acts in the motion after the first exchange"),
    "first exchange of the pair": (lambda d: d.update(between=[0, 1]), "between = [0, 1]: vehicles[1] is towed by "
                                                                       "vehicles[0]"),
    "the default between": (lambda d: d.pop("between"), "between = [0, 1] (the default): vehicles[1] is towed by "
                                                         "vehicles[0]"),
    "pairs": (lambda d: d.update(pairs=[{"between": [2, 0]}, {"between": [1, 0], "restitution": 0.2}]),
              "pairs[1].between = [1, 0]: vehicles[1] is towed by vehicles[0] (vehicles[1].hitch): a hitched pair is "
              "not watched for contact with each other"),
    "kingpin behind the CG": (_hitch(point=[-1, 0]), "vehicles[1].hitch.point = [-1, 0]: a semi-trailer's hitch "
                                                     "(kind \"fifth_wheel\") must lie ahead of its CG (point[0] > 0)"),
    "kind": (_hitch(kind="gooseneck"), "vehicles[1].hitch.kind = 'gooseneck': must be \"drawbar\""),
    "max_angle too large": (_hitch(max_angle="200 deg"), "vehicles[1].hitch.max_angle = '200 deg': must be in "
                                                         "(0, 180] deg"),
    "max_angle in rad": (_hitch(max_angle="4 rad"), "vehicles[1].hitch.max_angle = '4 rad' (229.2 deg): must be in "
                                                    "(0, 180] deg"),
    "max_angle 0": (_hitch(max_angle=0), "vehicles[1].hitch.max_angle = 0: must be in (0, 180] deg"),
    "max_angle below the articulation": (_hitch(max_angle="20 deg"), "vehicles[1].hitch.max_angle = '20 deg': the "
                                                                     "vehicles start at an articulation of 30 deg"),
    "max_angle units": (_hitch(max_angle="20 m"), "vehicles[1].hitch.max_angle = '20 m':"),
    "point missing": (lambda d: d["vehicles"][1]["hitch"].pop("point"), "vehicles[1].hitch.point: missing field"),
    "point of 3": (_hitch(point_on_tow=[1, 2, 3]), "vehicles[1].hitch.point_on_tow = [1, 2, 3]: must be a list of 2"),
    "point in kg": (_hitch(point=["5 kg", 0]), "vehicles[1].hitch.point[0] = '5 kg'"),
    "position off": (lambda d: d["vehicles"][1].update(position=[-6.0, -2.65]),
                     "vehicles[1].position = [-6.0, -2.65] (x, y = -6, -2.65 m): its hitch to vehicles[0] puts its CG "
                     "at (x, y) = (-6.49, -2.65) m, 0.4899 m away"),
    "speed off": (lambda d: d["vehicles"][1].update(speed=5), "vehicles[1].speed = 5 (5 m/s): its hitch to vehicles[0] "
                                                              "gives it a speed of 10.15 m/s"),
    "velocity off": (lambda d: d["vehicles"][1].update(velocity=[10, 0]),
                     "vehicles[1].velocity = [10, 0] ((vx, vy) = (10, 0) m/s): its hitch to vehicles[0] gives it "
                     "(vx, vy) = (10.14, -0.4061) m/s"),
    "course off": (lambda d: d["vehicles"][1].update(speed=10.14688, course=30),
                   "vehicles[1].speed = 10.14688 ((vx, vy) = (8.787, 5.073) m/s, course 30)"),
    "course alone": (lambda d: d["vehicles"][1].update(course=-2), "vehicles[1].course = -2: given without speed"),
    "a hitch not a table": (lambda d: d["vehicles"][1].update(hitch=0), "vehicles[1].hitch = 0: must be a "
                                                                        "table/object"),
}


@pytest.mark.parametrize("name", BAD)
def test_every_rule_is_refused_naming_the_field_and_the_value(name):
    change, words = BAD[name]
    message = _raise(change)
    assert message.startswith("case 'semi': ")
    assert words in message, message


def test_an_untowed_vehicle_still_needs_its_position_and_speed():
    assert "vehicles[0].position: missing field" in _raise(lambda d: d["vehicles"][0].pop("position"))
    assert "vehicles[2].speed: missing field" in _raise(lambda d: d["vehicles"][2].pop("speed"))


def test_an_unknown_hitch_key_is_named_and_ignored():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        case = case_from_dict(_with(_hitch(angle="20 deg")))
    assert case.motion.links == ((1, 0, "fifth_wheel"),)
    (w,) = [w for w in caught if issubclass(w.category, CaseWarning)]
    assert "case 'semi': vehicles[1].hitch.angle: unknown field, ignored (known: " in str(w.message)
    assert "kind, make, max_angle, model, name, notes, point, point_on_tow, source, to)" in str(w.message)


def test_one_bad_case_in_a_file_costs_that_case_only():
    bad = _with(lambda d: d.update(name="loop", between=[0, 1]))
    good = _with(lambda d: d.update(name="good"))
    cases = cases_from_data({"cases": [bad, good]})
    assert [c.valid for c in cases] == [False, True]
    assert "case 'loop': between = [0, 1]: vehicles[1] is towed by vehicles[0]" in cases[0].error
    assert cases[1].motion.links == ((1, 0, "fifth_wheel"),)


def _row(case):
    return as_arrays(case.inputs, jnp.float64)


def test_follow_tows_against_the_hand_calculation():
    """From inputs whose trailer has been put anywhere (as a sweep row might hold), the trailer's position, speed
    and course the hand calculation gives; the tractor's, the car's and the trailer's z, yaw and yaw rate as they
    were."""
    case = case_from_dict(SEMI)
    inputs = set_input(set_input(_row(case), "vehicles[1].position[0]", 40.0), "vehicles[1].speed", 0.0)
    inputs = set_input(inputs, "vehicles[1].course", 2.0)
    out = follow_tows(inputs, case.motion.links)
    v = out.vehicles[1]
    np.testing.assert_allclose(v.position, [*POSITION, 1.5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(v.speed, math.hypot(*VELOCITY), rtol=1e-12)
    np.testing.assert_allclose(v.course, math.atan2(VELOCITY[1], VELOCITY[0]), rtol=1e-12)
    for path in ("vehicles[1].yaw", "vehicles[1].yaw_rate", "vehicles[1].velocity_z", "vehicles[0].speed",
                 "vehicles[2].position[0]", "vehicles[2].course"):
        np.testing.assert_array_equal(get_input(out, path), get_input(inputs, path))
    assert follow_tows(inputs, ()) is inputs


INPUTS = ("vehicles[0].speed", "vehicles[0].course", "vehicles[0].yaw", "vehicles[0].yaw_rate",
          "vehicles[0].position[0]", "vehicles[1].yaw", "vehicles[1].yaw_rate")


def _followed(case, x):
    inputs = _row(case)
    for path, value in zip(INPUTS, x):
        inputs = set_input(inputs, path, value)
    v = follow_tows(inputs, case.motion.links).vehicles[1]
    return jnp.stack([v.position[0], v.position[1], v.speed, v.course])


@pytest.mark.slow
def test_follow_tows_in_jit_and_vmap_and_its_derivatives_match_finite_differences():
    """Compiled and mapped over rows: the hand calculation's row, and a row at rest; jacfwd of the trailer's
    followed position, speed and course by the tractor's speed, course, yaw, yaw rate and x, and the trailer's yaw
    and yaw rate, against central differences; finite (no NaN) with everything at rest."""
    case = case_from_dict(SEMI)
    rows = jax.jit(jax.vmap(lambda x: _followed(case, x)))
    jacobian = jax.jit(jax.jacfwd(lambda x: _followed(case, x)))
    hand = jnp.array([10.0, 0.0, 0.0, W0, 0.0, math.radians(30), W1])
    at_rest = jnp.array([0.0, 0.0, 0.0, 0.0, 0.0, math.radians(30), 0.0])
    x = jnp.array([10.0, 0.1, 0.05, W0, 0.0, math.radians(30), W1])
    eps = 1e-6
    steps = eps * jnp.eye(len(x))
    out = rows(jnp.concatenate([hand[None], at_rest[None], x + steps, x - steps]))
    np.testing.assert_allclose(out[0], [*POSITION, math.hypot(*VELOCITY), math.atan2(VELOCITY[1], VELOCITY[0])],
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out[1], [*POSITION, 0.0, 0.0], rtol=1e-12, atol=1e-12)
    fd = (out[2:2 + len(x)] - out[2 + len(x):]).T / (2 * eps)
    np.testing.assert_allclose(jacobian(x), fd, rtol=1e-6, atol=1e-8)
    assert np.all(np.isfinite(jacobian(at_rest)))


FOLLOWED = ("vehicles[1].position[0]", "vehicles[1].position[1]", "vehicles[1].speed", "vehicles[1].course")


@pytest.mark.parametrize("path", FOLLOWED)
def test_paths_a_hitch_sets_are_refused(path):
    """Sweeps, fits (unknowns and evidence) and set_input refuse a towed vehicle's position (x, y), speed and
    course, naming its tow; its z, yaw and yaw rate, and the tow's inputs, are accepted."""
    case = case_from_dict(SEMI)
    words = "vehicles[1] is towed by vehicles[0] ('Tractor'): its position (x, y), speed and course follow its tow's"
    assert words in follows_tow(case, path)
    with pytest.raises(CaseError, match=r"sweep over vehicles\[1\]\.") as err:
        check_sweep(case, {path: [1.0, 2.0]})
    assert words in str(err.value)
    with pytest.raises(CaseError, match=r"case 'semi': unknowns: vehicles\[1\]\.") as err:
        unknown_path(case, path)
    assert words in str(err.value)
    with pytest.raises(CaseError, match=r"case 'semi': evidence: vehicles\[1\]\."):
        evidence_kind(case, path)
    with pytest.raises(PathError, match=r"set_input 'vehicles\[1\]\..*': vehicles\[1\] is towed by vehicles\[0\]"):
        set_input(case.inputs, path, 1.0, links=case.motion.links)
    set_input(case.inputs, path, 1.0)  # without the links, inputs alone say nothing of the hitch


def test_paths_a_hitch_leaves_free_are_accepted():
    case = case_from_dict(SEMI)
    for path in ("vehicles[1].position[2]", "vehicles[1].yaw", "vehicles[1].yaw_rate", "vehicles[1].mass",
                 "vehicles[0].speed", "vehicles[0].position[0]", "vehicles[2].speed"):
        assert follows_tow(case, path) is None
        unknown_path(case, path)
        set_input(case.inputs, path, 1.0, links=case.motion.links)
    check_sweep(case, {"vehicles[0].speed": [8.0, 10.0], "vehicles[1].yaw": [0.4, 0.5]})
    # the trailer's course follows its tow, not its yaw; its z, where the file gives no position, its cg_height
    assert input_ties(case, ["vehicles[1].yaw", "vehicles[1].cg_height"]) == ((1, "vehicles[1].position[2]"),)
    def unhitched(d):
        del d["vehicles"][1]["hitch"]
        d["vehicles"][1].update(position=list(POSITION), speed=10)
    plain = case_from_dict(_with(unhitched))
    assert path_key(plain) != path_key(case)
    assert follows_tow(plain, "vehicles[1].speed") is None


def test_a_toml_file_gives_the_hitch_as_a_table(tmp_path):
    """The hitch in TOML: a table under its vehicle; loaded from the file as from the dict."""
    lines = ['name = "semi"', "between = [2, 1]"]
    for v in SEMI["vehicles"]:
        lines.append("[[vehicles]]")
        lines += [f"{k} = {_toml(x)}" for k, x in v.items() if k != "hitch"]
        if "hitch" in v:
            lines.append("[vehicles.hitch]")
            lines += [f"{k} = {_toml(x)}" for k, x in v["hitch"].items()]
    lines += ["[contact]", *(f"{k} = {_toml(x)}" for k, x in SEMI["contact"].items()), "[road]", "friction = 0.7"]
    path = tmp_path / "semi.toml"
    path.write_text("\n".join(lines) + "\n")
    (case,) = load_cases(path)
    assert case.motion.links == ((1, 0, "fifth_wheel"),)
    np.testing.assert_allclose(case.inputs.vehicles[1].position, [*POSITION, 1.5], rtol=0, atol=1e-12)


def _toml(x):
    return "[" + ", ".join(_toml(e) for e in x) + "]" if isinstance(x, list) else \
        f'"{x}"' if isinstance(x, str) else repr(x)
