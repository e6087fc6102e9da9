"""``ks_jax.solve``: a case alone, in a batch and in a sweep gives the same results (programs rounded
differently), and the results the model leaves undefined are said so."""

import copy
import json
import math
import tomllib
from pathlib import Path

import jax
import numpy as np
import pytest

import ks_jax
from ks_jax.case import CaseError, case_from_dict, get_input, load_case
from ks_jax.model.motion import RestResult
from samples import US_CASE, run_cli


def _alone_batched_and_swept(case, swept=True):
    """[(status, {path: np.ndarray})] of ``case`` solved alone, of the two rows of a batch of it twice, and where
    ``swept``, of the first point of a sweep of two points (its own speed twice). ``solve`` compiles one case
    unbatched and two cases with vmap, and the sweep its own chunk of the case's stages, all with
    ``compilation.QUICK_CPU``: programs which XLA fuses and rounds differently. (That the quick settings give the
    values of XLA's defaults is checked apart, once: tests/model/test_transforms.py::
    test_solve_compiles_with_the_quick_settings_and_gets_the_defaults_values for ``solve`` and
    tests/sweeps/test_sweep.py::test_a_small_sweep_compiles_quick_and_gets_the_values_of_xla_defaults for
    ``sweep``.)"""
    out = []
    for sol in (ks_jax.solve(case), *ks_jax.solve([case, case])):
        leaves = jax.tree_util.tree_flatten_with_path(sol.result)[0]
        # a vehicle's motion to rest (result.rest[i]) is named as its other results are: vehicles[i].rest_position
        out.append((sol.status, {jax.tree_util.keystr(k).replace(".rest[", ".vehicles["): np.asarray(x, float)
                                 for k, x in leaves}))
    if not swept:
        return out
    columns = {}
    for path, x in out[0][1].items():
        if path == ".contact.status" or (path == ".contact.time" and not case.auto_point):
            continue  # the sweep's status is its own; a first-contact time is automatic contact's
        if path.startswith(".interactions."):
            continue  # the later exchanges, as a sweep names them (exchanges[k]): tests/test_interactions.py
        if case.fixed and path.startswith(".vehicles[1]."):
            continue  # a fixed object has no results to sweep
        columns[path] = None if np.ndim(x) == 0 else [f"{path[1:]}[{i}]" for i in range(len(x))]
    vehicle = "vehicles[0]" if case.fixed else "vehicles[1]"  # against a fixed object: the one vehicle
    speed = float(get_input(case.inputs, f"{vehicle}.speed"))
    swept = ks_jax.sweep(case, {f"{vehicle}.speed": [speed, speed]}, mode="zip",
                         outputs=[c for p, cols in columns.items() for c in (cols or [p[1:]])])
    results = {p: np.asarray(float(swept[p[1:]][0]) if cols is None else [float(swept[c][0]) for c in cols])
               for p, cols in columns.items()}
    results[".contact.status"] = np.asarray(float(swept["status"][0]))
    out.append((ks_jax.status_text(swept["status"][0]), results))
    return out


@pytest.mark.parametrize("name", sorted(p.name for p in (Path(ks_jax.__file__).parent / "cases").iterdir()
                                         if p.suffix in (".json", ".toml")))
@pytest.mark.slow
def test_one_case_solved_alone_equals_it_solved_in_a_batch(name):
    """``solve`` compiles a case alone without vmap and two cases with it, and ``sweep`` its own three stages:
    programs which XLA fuses and rounds differently. Every result agrees (to 1e-9 of its scale). A quantity that
    is 0 up to rounding (the tangential impulse of the inline seed crashes) is where a double-where's stand-in
    could leak: alone, the seed chapter's crash gave 1.1 N s of tangential impulse, in a batch 0. Every result of
    the exchange is swept in the cases without a road; a case with a road is swept by the matrix
    (tests/command_matrix.py, ``check_sweep``: the sweep's results at the case's own values against ``solve``), as
    its sweep compiles the watched motion once more."""
    case = load_case(Path(ks_jax.__file__).parent / "cases" / name)
    swept = case.motion is None
    (status, alone), *others = _alone_batched_and_swept(case, swept=swept)
    fields = [f".contact.{f}" for f in ks_jax.ContactResult._fields]
    fields += [f".vehicles[{i}].{f}" for i in range(2) for f in ks_jax.VehicleResult._fields]
    if case.motion is not None:
        moving = [0] if case.fixed else [0, 1]  # a fixed object does not move
        # with the path of every step, which solve keeps for a file's few cases (ks_jax.solve.cases.PATH_BYTES)
        fields += [f".vehicles[{i}].{f}" for i in moving for f in RestResult._fields]
    later = {p for p in alone if p.startswith(".interactions.")}  # the watched motion's, with a road
    assert sorted(set(alone) - later) == sorted(fields) and len(others) == 2 + swept
    assert bool(later) == (case.motion is not None)
    for (other_status, other), what in zip(others, ("batch row 0", "batch row 1", "sweep")):
        assert other_status == status, what
        assert sorted(other) == sorted(alone) if what != "sweep" else set(other) <= set(alone), what
        for path, b in other.items():
            scale = 1e-9 * (1.0 + np.nanmax(np.abs(alone[path])))
            np.testing.assert_allclose(b, alone[path], rtol=0, atol=scale, err_msg=f"{what}: {path}")


@pytest.mark.parametrize("name, yaws, friction, restitution, normal", [
    ("seed_001_lucid_kia.toml", (0, 0), 0.0, 0.0, None),
    ("seed_001_lucid_kia.toml", (90, 0), 1.0, 1.0, None),
    ("seed_000_saturn_pontiac.json", (180, 180), 1.0, 1.0, 180),
])
@pytest.mark.slow
def test_flags_and_ees_of_a_quantity_zero_to_rounding_are_the_same_alone_batched_and_swept(
        name, yaws, friction, restitution, normal):
    """Seed crashes changed so that a result hangs on a quantity that is 0 up to rounding, solved alone, in
    a batch and in a sweep (programs rounded differently). By hand: at mu = 0 an impulse with no tangential part
    does not slide (|T_c| = mu N_c = 0: ``sliding`` False); a sticking elastic exchange (eps = 1) loses no
    energy (u' = -u), so both EES are 0. Before, the first slid in a batch and not alone, and the others'
    EES were NaN (a loss of -1e-9 J) in one program and 1e-7 m/s in the other."""
    path = Path(ks_jax.__file__).parent / "cases" / name
    d = tomllib.loads(path.read_text()) if path.suffix == ".toml" else json.loads(path.read_text())
    d.pop("reference", None)
    for vehicle, yaw in zip(d["vehicles"], yaws):
        vehicle["yaw"] = yaw
    d["contact"].update(friction=friction, restitution=restitution)
    if normal is not None:
        d["contact"]["normal"] = normal
    for status, res in _alone_batched_and_swept(case_from_dict(d)):
        assert status == "ok"
        magnitude = float(res[".contact.impulse_magnitude"])
        if friction == 0.0:
            assert not bool(res[".contact.sliding"])
            assert abs(float(res[".contact.impulse_tangential"])) <= 1e-12 * magnitude
        else:
            scale = magnitude * float(np.linalg.norm(res[".contact.closing_velocity"]))
            assert abs(float(res[".contact.energy_loss"])) <= 1e-12 * scale
            assert [float(res[f".vehicles[{i}].ees"]) for i in range(2)] == [0.0, 0.0]


def test_a_centroid_on_both_faces_has_crush_zero_not_minus_zero(tmp_path, capsys):
    """A rear-end whose centroid lies on the lead car's rear face and the follower's front face: both
    crushes are 0 (docs/model.md, "Results": the distance from P to leaving the box), written 0.0, never -0.0,
    and the EES is undefined (null) with the report's note."""
    d = copy.deepcopy(US_CASE)
    a, b = d["vehicles"]
    a.update(yaw=0, position=["0 ft", "0 ft"], speed="15 mph")  # rear face at x = 7 - 15 = -8 ft
    b.update(yaw=0, position=["-16 ft", "0 ft"], speed="40 mph", yaw_rate=0)  # front face at -16 + 8 = -8 ft
    d["contact"] = {"point": ["-8 ft", "0.5 ft", "1.8 ft"], "normal": 0, "restitution": 0.15, "friction": 0.6}
    path = tmp_path / "face.json"
    path.write_text(json.dumps(d))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    res = json.loads(out)["cases"][0]
    assert code == 0 and res["contact"]["status"] == "ok"
    assert [v["crush"] for v in res["vehicles"]] == [0.0, 0.0] and '"crush": -0.0' not in out
    assert [v["ees"] for v in res["vehicles"]] == [None, None]


def test_no_impulse_has_no_pdof(tmp_path, capsys):
    """Both vehicles at rest: separating, no impulse, so no principal direction of force."""
    d = copy.deepcopy(US_CASE)
    d["vehicles"][1]["speed"] = "0 mph"
    del d["vehicles"][1]["yaw_rate"]
    path = tmp_path / "rest.json"
    path.write_text(json.dumps(d))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    res = json.loads(out)["cases"][0]
    assert code == 0 and res["contact"]["status"] == "separating" and res["contact"]["impulse_magnitude"] == 0.0
    assert all(v["pdof"] is None and v["pdof_clock"] is None for v in res["vehicles"])
    assert res["contact"]["impulse_azimuth"] is None and res["contact"]["impulse_elevation"] is None
    code, out, _ = run_cli(capsys, "solve", str(path))
    assert out.count("undefined (no impulse)") == 3 and "no impulse" in out.split("sliding at separation")[1][:40]
    assert "undefined (no impulse)" in out.split("azimuth / elevation")[1][:40]


@pytest.mark.slow
def test_overflowing_case_is_reported_not_drawn_with_nan(tmp_path, capsys):
    d = copy.deepcopy(US_CASE)
    d["vehicles"][1]["speed"] = 1e300  # m/s: finite, but its energy is not
    path = tmp_path / "huge.json"
    path.write_text(json.dumps(d))
    code, out, err = run_cli(capsys, "solve", str(path), "--plot", str(tmp_path / "huge.png"))
    assert code == 1 and "status: invalid: the results overflow" in out and "undefined" not in out
    assert "not solved" in err and (tmp_path / "huge.png").read_bytes()[:4] == b"\x89PNG"
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    status = ("invalid: the results overflow (an input is far out of scale, e.g. a speed of 1e200 m/s or a mass of "
              "1e-300 kg)")
    named = "; the input farthest out of scale: vehicles[1].speed = 1e+300 m/s"
    assert json.loads(out)["cases"][0] == {"name": "units check", "vehicles": [], "contact": {"status": status + named}}
    # the input named is the one out of scale, not survey coordinates: a speed of 1e200 mph is
    # 1e200 * 0.44704 m/s, in a scene moved 300 km east and north (a mass of 1e-300 kg, the other way out of
    # scale, is refused where the file is read: tests/test_hostile.py)
    far = copy.deepcopy(US_CASE)
    far["vehicles"][0]["speed"] = "1e200 mph"
    for v in far["vehicles"]:
        v["position"] = [f"{300000 + 0.3048 * float(x.split()[0])} m" for x in v["position"]]
    far["contact"]["point"] = [f"{300000 + 0.3048 * float(x.split()[0])} m" for x in far["contact"]["point"][:2]] + \
        [far["contact"]["point"][2]]
    path.write_text(json.dumps({"cases": [far, US_CASE]}))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    far_res, good = json.loads(out)["cases"]
    assert code == 1 and good["contact"]["status"] == "ok"
    assert far_res["contact"]["status"] == (status + "; the input farthest out of scale: "
                                            "vehicles[0].speed = 4.4704e+199 m/s")


def test_state_needs_a_height_for_a_2d_position():
    for make, message in (
            (lambda: ks_jax.Contact.create([-2.25, 0.0], azimuth=0.0), r"Contact.create: point has shape \(2,\)"),
            (lambda: ks_jax.Vehicle.create(1500.0, [500.0, 2000.0], 4.5, 1.8), r"Vehicle.create: inertia has shape"),
            (lambda: ks_jax.State.create([0, 0, 0.5], velocity=[1, 2, 3, 4]), r"State.create: velocity has shape"),
            (lambda: ks_jax.solve("case.json"), "solve takes a Case"),
            (lambda: ks_jax.load_case(Path(__file__).parent), "is a directory")):
        with pytest.raises((ValueError, TypeError), match=message):
            make()
    with pytest.raises(ValueError, match=r"position \(x, y\) has no z"):
        ks_jax.State.create([1.0, 2.0], speed=3.0)
    s = ks_jax.State.create([1.0, 2.0], speed=3.0, cg_height=0.6)
    np.testing.assert_array_equal(np.asarray(s.position), [1.0, 2.0, 0.6])


def test_ees_undefined_when_crush_is_rounding_error():
    # a centroid on a box face gives crush ~1e-16 m: Burg's split is undefined there, not 100 % / 0 %
    import jax.numpy as jnp

    from ks_jax.model.results import ees_pair

    e1, e2 = ees_pair(jnp.float64(2e4), jnp.float64(2.2e-16), jnp.float64(0.0), 1500.0, 1400.0, 9.0)
    assert np.isnan(e1) and np.isnan(e2)
    # a real crush splits the energy in proportion (docs/model.md, "Results"): E_i = E C_i / (C_1 + C_2)
    e1, e2 = ees_pair(jnp.float64(2e4), jnp.float64(0.3), jnp.float64(0.1), 1500.0, 1400.0, 9.0)
    assert float(e1) == pytest.approx(math.sqrt(2 * 2e4 * 0.75 / 1500.0), rel=1e-12)
    assert float(e2) == pytest.approx(math.sqrt(2 * 2e4 * 0.25 / 1400.0), rel=1e-12)


HEAD_ON = {
    "name": "head-on, inline",
    "vehicles": [
        {"mass": 1500, "inertia": [500, 2000, 2200], "length": 4.5, "width": 1.8, "height": 1.4, "cg_to_front": 2.25,
         "cg_height": 0.5, "position": [0, 0], "yaw": 0, "speed": 10},
        {"mass": 1800, "inertia": [600, 2400, 2600], "length": 4.5, "width": 1.8, "height": 1.4, "cg_to_front": 2.25,
         "cg_height": 0.5, "position": [4.5, 0], "yaw": 180, "speed": 10}],
    "contact": {"point": [2.25, 0, 0.5], "normal": 180, "restitution": 0.1, "friction": 0.5},
}


@pytest.mark.slow
def test_a_vehicle_brought_to_rest_has_no_course_after(tmp_path, capsys):
    """Inline head-on, so the stick impulse (docs/model.md, "The impulse exchange", step 6): v' = vc (1 + eps) - eps v
    with vc = (1500 * 10 - 1800 * 10) / 3300 = -10/11 m/s. Vehicle 2 ends at 0 m/s: at rest, it has no course
    after (null, "undefined (at rest)", NaN in a sweep); vehicle 1 ends at -2 m/s, course 180 deg. At 9 and
    11 m/s vehicle 2 ends at +0.5 and -0.5 m/s: courses 0 and 180. An explicit contact has no first-contact
    time: null in the JSON, and refused as a sweep output."""
    path = tmp_path / "head_on.json"
    path.write_text(json.dumps(HEAD_ON))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    d = json.loads(out)["cases"][0]
    assert code == 0 and d["contact"]["status"] == "ok" and d["contact"]["time"] is None
    v1, v2 = d["vehicles"]
    assert v2["speed_after"] == pytest.approx(0.0, abs=1e-12) and v2["course_after"] is None
    assert v1["speed_after"] == pytest.approx(2.0, rel=1e-12) and v1["course_after"] == pytest.approx(180.0, abs=1e-9)
    code, out, _ = run_cli(capsys, "solve", str(path))
    courses = [line.split("course after")[1].strip() for line in out.splitlines() if "course after" in line]
    assert courses == ["180.0 deg", "undefined (at rest)"]
    case = load_case(path)
    swept = ks_jax.sweep(case, {"vehicles[1].speed": [9.0, 10.0, 11.0]}, outputs=["vehicles[1].course_after"])
    np.testing.assert_allclose(swept["vehicles[1].course_after"], [0.0, np.nan, 180.0], atol=1e-9)
    assert swept.undefined == {"vehicles[1].course_after": 1} and "at rest" in swept.summary()
    with pytest.raises(CaseError, match="'contact.time' is the first-contact time of automatic contact"):
        ks_jax.sweep(case, {"vehicles[1].speed": [9.0]}, outputs=["contact.time"])


def test_directions_are_shown_in_0_to_360_and_clock_halves_go_clockwise():
    """docs/model.md, "Results": directions in [0, 360), so 359.97 shown to one digit is 0.0, not 360.0; and the
    clock is the nearest hour, a half hour going clockwise (15 deg is 1 o'clock, as 45 deg is 2)."""
    import jax.numpy as jnp

    from ks_jax.model.results import clock
    from ks_jax.report import angle_text as _deg

    assert [_deg(x) for x in (359.97, 359.94, 0.04, 180.0, -0.01)] == ["0.0", "359.9", "0.0", "180.0", "0.0"]
    pdof = [0.0, 14.99, 15.0, 45.0, 75.0, 135.0, 165.0, 255.0, 315.0, 344.99, 345.0, 359.99]
    assert clock(jnp.array(pdof)).tolist() == [12, 12, 1, 2, 3, 5, 6, 9, 11, 11, 12, 12]
