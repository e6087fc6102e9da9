"""Case files, units at the edge, the command line and every class of bad input (MODEL.md section 6)."""

import contextlib
import copy
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax import units as U
from ks_jax.case import CaseError, CaseWarning, at_rest_after, case_from_dict, defined_output, load_case
from ks_jax.cli import main
from ks_jax.stored import _CACHE_ENTRY, prune_cache

# A case written in US units; its SI twin below is written by hand from the exact unit definitions.
US_CASE = {
    "name": "units check",
    "vehicles": [
        {"name": "A", "weight": "3000 lbf", "inertia": ["400 kg*m^2", "1800 kg*m^2", "2000 kg*m^2"],
         "length": "15 ft", "width": "6 ft", "height": "4.5 ft", "cg_to_front": "7 ft", "cg_height": "1.8 ft",
         "position": ["0 ft", "0 ft"], "yaw": "90 deg", "speed": "0 mph"},
        {"name": "B", "mass": "100 slug", "inertia": [[300, 0, 0], [0, 1500, 0], [0, 0, "1200 lbf*ft*s^2"]],
         "length": "16 ft", "width": "6 ft", "height": "4.5 ft", "cg_to_front": "8 ft", "cg_height": "1.8 ft",
         "position": ["-10 ft", "-2 ft"], "yaw": 0, "speed": "30 mph", "yaw_rate": "10 deg/s"},
    ],
    "contact": {"point": ["-1 ft", "-1.5 ft", "2 ft"], "normal": 15, "normal_pitch": "2 deg",
                "restitution": 0.2, "friction": 0.4},
}


def si_twin():
    ft, g0 = 0.3048, 9.80665
    lbf = 0.45359237 * g0
    return {
        "name": "units check (SI)",
        "vehicles": [
            {"mass": 3000 * lbf / g0, "inertia": [400, 1800, 2000], "length": 15 * ft, "width": 6 * ft,
             "height": 4.5 * ft, "cg_to_front": 7 * ft, "cg_height": 1.8 * ft, "position": [0, 0, 1.8 * ft],
             "yaw": 90, "velocity": [0, 0]},
            {"mass": 100 * lbf / ft, "inertia": [[300, 0, 0], [0, 1500, 0], [0, 0, 1200 * lbf * ft]],
             "length": 16 * ft, "width": 6 * ft, "height": 4.5 * ft, "cg_to_front": 8 * ft, "cg_height": 1.8 * ft,
             "position": [-10 * ft, -2 * ft], "yaw": 0, "speed": 30 * 1609.344 / 3600,
             "angular_velocity": [0, 0, 10]},
        ],
        "contact": {"point": [-1 * ft, -1.5 * ft, 2 * ft], "normal": 15, "normal_pitch": 2,
                    "restitution": 0.2, "friction": 0.4},
    }


def run_cli(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_unit_strings_equal_si_numbers():
    a = ks_jax.solve(case_from_dict(US_CASE)).to_dict()
    b = ks_jax.solve(case_from_dict(si_twin())).to_dict()
    assert a["contact"]["status"] == "ok"
    np.testing.assert_allclose(a["contact"]["impulse"], b["contact"]["impulse"], rtol=1e-12)
    for va, vb in zip(a["vehicles"], b["vehicles"]):
        np.testing.assert_allclose(va["velocity_after"], vb["velocity_after"], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(va["angular_velocity_after"], vb["angular_velocity_after"], rtol=1e-12, atol=1e-12)


def test_parse_quantity_rules():
    assert U.parse_quantity("21 mph", "velocity") == pytest.approx(21 * 0.44704, rel=1e-12)
    assert U.parse_quantity("2300 lbf*ft*s^2", "inertia") == pytest.approx(2300 * 4.4482216152605 * 0.3048, rel=1e-12)
    assert U.parse_quantity(30, "angle") == pytest.approx(math.radians(30))
    assert U.parse_quantity("30 deg", "angle") == pytest.approx(math.radians(30))
    assert U.parse_quantity(45, "angular_velocity") == pytest.approx(math.radians(45))
    assert U.parse_quantity("0.06 s", "time") == pytest.approx(0.06)
    assert U.parse_quantity("155.75 slug", "mass") == pytest.approx(155.75 * 14.593902937206364, rel=1e-12)
    with pytest.raises(U.UnitError, match="dimension"):
        U.parse_quantity("21 mph", "mass")
    with pytest.raises(U.UnitError, match="unknown unit"):
        U.parse_quantity("21 furlongs_per_blink", "velocity")


def test_unit_strings_read_one_number_and_its_unit():
    """A thousands separator, a decimal comma, a second number or an expression is refused, where pint
    alone would read "1 500 kg" as 500 kg, "4,5 m" as 45 m and "30 mph 2" as 60 mph. A hyphen between
    unit names is a product, as US reports write energies and impulses; a rate needs an angle in its unit
    (Hz or 1/s could count radians or turns); restitution and friction take no unit (pint would take an
    angle: "30 deg" as 0.52)."""
    for text, kind in [("1 500 kg", "mass"), ("3 000 kg", "mass"), ("4,5 m", "length"), ("12,5 km/h", "velocity"),
                       ("0,1", "dimensionless"), ("30 mph 2", "velocity"), ("0.1 0.2", "dimensionless"),
                       ("5 kg + 3 kg", "mass"), ("1 250 mm", "length"), ("a", "velocity"), ("mph", "velocity")]:
        with pytest.raises(U.UnitError, match="one number, then its unit"):
            U.parse_quantity(text, kind)
    # the seed chapter's energy and impulse as its US panel writes them (MODEL.md section 7)
    assert U.parse_quantity("14117.71 ft-lbf", "energy") == pytest.approx(14117.71 * 0.3048 * 4.4482216152605, rel=1e-12)
    assert U.parse_quantity("1336.904 lbf-s", "impulse") == pytest.approx(5946.847, abs=2e-3)
    assert U.parse_quantity("2300 lbf-ft-s^2", "inertia") == U.parse_quantity("2300 lbf*ft*s^2", "inertia")
    assert U.parse_quantity("60 rpm", "angular_velocity") == pytest.approx(2 * math.pi)
    assert U.parse_quantity("2 rad/s", "angular_velocity") == 2.0
    for text in ("1 Hz", "2 1/s"):
        with pytest.raises(U.UnitError, match="needs an angle"):
            U.parse_quantity(text, "angular_velocity")
    with pytest.raises(U.UnitError, match="takes no unit"):
        U.parse_quantity("30 deg", "dimensionless")


def test_unit_definitions_kept_in_a_folder_read_the_same(tmp_path, monkeypatch):
    """With ``units.REGISTRY_CACHE`` (the command line sets it) pint keeps its parsed unit definitions in that
    folder and reads them back in the next process; quantities read that way equal the exact definitions, and
    a folder that cannot be made (under a file) is passed over: the definitions are parsed as without one."""
    lbf, ft = 0.45359237 * 9.80665, 0.3048
    texts = [("21 mph", "velocity", 21 * 1609.344 / 3600), ("2300 lbf*ft*s^2", "inertia", 2300 * lbf * ft),
             ("155.75 slug", "mass", 155.75 * lbf / ft), ("14117.71 ft-lbf", "energy", 14117.71 * ft * lbf),
             ("60 rpm", "angular_velocity", 2 * math.pi), ("12 in", "length", 12 * 0.0254)]
    (tmp_path / "a_file").write_text("not a folder")
    folder = tmp_path / "units"
    try:
        for where in (folder, folder, tmp_path / "a_file" / "units"):  # written, read back, unusable
            monkeypatch.setattr(U, "REGISTRY_CACHE", where)
            U._registry.cache_clear()
            for text, kind, want in texts:
                assert U.parse_quantity(text, kind) == pytest.approx(want, rel=1e-12), (where, text)
            if where == folder:
                assert any(folder.iterdir())
    finally:
        U._registry.cache_clear()


def test_seed_case_files_json_and_toml(capsys):
    # the manual's panel for chapter 000 and the hand calculation of chapter 001, through the CLI
    from importlib import resources

    root = resources.files("ks_jax.cases")
    code, out, _ = run_cli(capsys, "solve", str(root / "seed_000_saturn_pontiac.json"), "--json")
    assert code == 0
    res = json.loads(out)["cases"][0]
    assert res["contact"]["impulse_magnitude"] == pytest.approx(5946.847, abs=1e-3)
    assert res["contact"]["energy_loss"] == pytest.approx(19141.047, abs=5e-3)
    assert [v["ees"] / U.MPH for v in res["vehicles"]] == pytest.approx([11.281, 2.213], abs=1e-3)
    assert [v["crush"] / U.FT for v in res["vehicles"]] == pytest.approx([1.396, 0.059], abs=1e-4)
    assert [v["pdof"] for v in res["vehicles"]] == pytest.approx([180.0, 0.0])
    assert '"pdof": -0.0' not in out and math.copysign(1.0, res["vehicles"][1]["pdof"]) == 1.0  # [0, 360)
    assert [v["pdof_clock"] for v in res["vehicles"]] == [6, 12]
    # inline, centroid at CG height on the axis: the impulse is all along the normal (by hand: no tangential part)
    assert abs(res["contact"]["impulse_tangential"]) <= 1e-9 * res["contact"]["impulse_magnitude"]
    code, out, _ = run_cli(capsys, "solve", str(root / "seed_001_lucid_kia.toml"), "--json")
    res = json.loads(out)["cases"][0]
    assert res["contact"]["impulse_magnitude"] == pytest.approx(6571.96, rel=1e-3)
    assert abs(res["contact"]["impulse_tangential"]) <= 1e-9 * res["contact"]["impulse_magnitude"]
    assert [v["speed_after"] / U.FT for v in res["vehicles"]] == pytest.approx([16.82, 14.62], abs=0.01)
    assert res["contact"]["energy_loss"] / U.FT_LBF == pytest.approx(14624.38, rel=1e-3)


# One case solved alone, in a batch of two and in a sweep of two points (its own speed twice), in a
# subprocess without the tests' XLA flags, as users run it (tests/conftest.py compiles this process's programs
# with cheaper settings): ``solve``'s programs then compile with ``ks_jax.quick``'s settings, and the sweep's
# (two points, quick too) are made to compile with XLA's defaults (``QUICK_POINTS`` 0), as a large sweep's
# are. The leak below came from how XLA fused and rounded one of the programs.
# Prints, for each of the four solutions, its status and its results by path (the sweep's components
# put together into vectors).
_ALONE_BATCHED_AND_SWEPT = r"""
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import ks_jax
from ks_jax.case import case_from_dict, get_input, load_case
from ks_jax.types import status_text
spec = json.loads(sys.argv[1])
case = load_case(spec["path"]) if "path" in spec else case_from_dict(spec["case"])
out = []
for sol in (ks_jax.solve(case), *ks_jax.solve([case, case])):
    leaves = jax.tree_util.tree_flatten_with_path(sol.result)[0]
    out.append({"status": sol.status,
                "results": {jax.tree_util.keystr(k): np.asarray(x, float).tolist() for k, x in leaves}})
columns = {}
for path, x in out[0]["results"].items():
    if path == ".contact.status" or (path == ".contact.time" and not case.auto_point):
        continue  # the sweep's status is its own; a first-contact time is automatic contact's
    columns[path] = None if np.ndim(x) == 0 else [f"{path[1:]}[{i}]" for i in range(len(x))]
speed = float(get_input(case.inputs, "vehicles[1].speed"))
ks_jax.sweeps.QUICK_POINTS = 0  # compiled at XLA's defaults
swept = ks_jax.sweep(case, {"vehicles[1].speed": [speed, speed]}, mode="zip",
                     outputs=[c for p, cols in columns.items() for c in (cols or [p[1:]])])
results = {p: float(swept[p[1:]][0]) if cols is None else [float(swept[c][0]) for c in cols]
           for p, cols in columns.items()}
results[".contact.status"] = float(swept["status"][0])
out.append({"status": status_text(swept["status"][0]), "results": results})
print(json.dumps(out))
"""


def _alone_batched_and_swept(kit, spec):
    """[(status, {path: np.ndarray})] of the case alone, of the two rows of the batch and of the sweep's first
    point."""
    env = kit.xla_default_env(JAX_PLATFORMS="cpu", JAX_COMPILATION_CACHE_DIR=os.environ["KS_JAX_TEST_COMPILE_CACHE"],
                              JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    done = subprocess.run([sys.executable, "-c", _ALONE_BATCHED_AND_SWEPT, json.dumps(spec)], capture_output=True,
                          text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return [(s["status"], {k: np.asarray(v, float) for k, v in s["results"].items()})
            for s in json.loads(done.stdout.strip().splitlines()[-1])]


@pytest.mark.parametrize("name", sorted(p.name for p in (Path(ks_jax.__file__).parent / "cases").iterdir()
                                         if p.suffix in (".json", ".toml")))
def test_one_case_solved_alone_equals_it_solved_in_a_batch(name, kit):
    """``solve`` compiles a case alone without vmap and two cases with it, and ``sweep`` its own three
    stages: programs which XLA fuses and rounds differently. Every result agrees (to 1e-9 of its scale). A
    quantity that is 0 up to rounding (the tangential impulse of the inline seed crashes) is where a
    double-where's stand-in could leak: alone, the seed chapter's crash gave 1.1 N s of tangential impulse,
    in a batch 0."""
    path = Path(ks_jax.__file__).parent / "cases" / name
    (status, alone), *others = _alone_batched_and_swept(kit, {"path": str(path)})
    fields = [f".contact.{f}" for f in ks_jax.ContactResult._fields]
    fields += [f".vehicles[{i}].{f}" for i in range(2) for f in ks_jax.VehicleResult._fields]
    assert sorted(alone) == sorted(fields) and len(others) == 3
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
def test_flags_and_ees_of_a_quantity_zero_to_rounding_are_the_same_alone_batched_and_swept(
        name, yaws, friction, restitution, normal, kit):
    """Seed crashes changed so that a result hangs on a quantity that is 0 up to rounding, solved alone, in
    a batch and in a sweep (programs rounded differently). By hand: at mu = 0 an impulse with no tangential part
    does not slide (|T_c| = mu N_c = 0: ``sliding`` False); a sticking elastic exchange (eps = 1) loses no
    energy (u' = -u), so both EES are 0. Before, the first slid in a batch and not alone, and the others'
    EES were NaN (a loss of -1e-9 J) in one program and 1e-7 m/s in the other."""
    from ks_jax.case import _read

    d = _read(Path(ks_jax.__file__).parent / "cases" / name)
    d.pop("reference", None)
    for vehicle, yaw in zip(d["vehicles"], yaws):
        vehicle["yaw"] = yaw
    d["contact"].update(friction=friction, restitution=restitution)
    if normal is not None:
        d["contact"]["normal"] = normal
    for status, res in _alone_batched_and_swept(kit, {"case": d}):
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
    crushes are 0 (MODEL.md section 4: the distance from P to leaving the box), written 0.0, never -0.0,
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


def test_json_keys_are_model_section_4(tmp_path, capsys):
    path = tmp_path / "c.json"
    path.write_text(json.dumps(US_CASE))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    res = json.loads(out)["cases"][0]
    assert set(res) == {"name", "contact", "vehicles"}
    assert set(res["contact"]) == set(ks_jax.ContactResult._fields)
    assert set(res["vehicles"][0]) == set(ks_jax.VehicleResult._fields) | {"name"}
    assert res["contact"]["status"] == "ok"
    # the JSON's impulse is what the Python API gives
    direct = ks_jax.solve(load_case(path))
    np.testing.assert_allclose(res["contact"]["impulse"], direct.result.contact.impulse, rtol=1e-12)


def test_text_report_has_both_unit_systems(tmp_path, capsys):
    path = tmp_path / "c.json"
    path.write_text(json.dumps(US_CASE))
    code, out, _ = run_cli(capsys, "solve", str(path))
    assert code == 0
    for word in ("impulse", "lbf s", "N s", "ft lbf", "mph", "PDOF", "EES", "crush", "sliding"):
        assert word in out


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


def test_demo_prints_both_seed_chapters(capsys):
    code, out, _ = run_cli(capsys, "demo")
    assert code == 0
    assert "Saturn L300" in out and "Lucid Air" in out
    assert "5,946.847 N s" in out and "1,336.904 lbf s" in out
    assert "The crushes agree by construction" in out
    # the note on chapter 001's arithmetic states true numbers
    assert "1.1 x 61.04 slug x 22 ft/s = 1477.17 lbf s" in out and f"{1.1 * 61.04 * 22:.2f}" == "1477.17"
    assert "6571.96 N s is 1477.44 lbf s" in out and f"{6571.96 / U.LBF_S:.2f}" == "1477.44"
    assert "1,477.169 lbf s" in out and "exact 1477.169 lbf s (6570.775 N s)" in out


def _bad(mutate):
    d = copy.deepcopy(US_CASE)
    mutate(d)
    return d


BAD = {
    "mass <= 0": (lambda d: d["vehicles"][0].update(weight="-1200 lbf"), r"vehicles\[0\]\.weight = '-1200 lbf'.*positive"),
    "zero mass": (lambda d: d["vehicles"][1].update(mass=0), r"vehicles\[1\]\.mass = 0: mass must be positive"),
    "inertia <= 0": (lambda d: d["vehicles"][0].update(inertia=[400, -5, 2000]), r"vehicles\[0\]\.inertia\[1\].*positive"),
    "inertia tensor not PD": (lambda d: d["vehicles"][1].update(inertia=[[1, 2, 0], [2, 1, 0], [0, 0, 1]]),
                              r"vehicles\[1\]\.inertia.*positive definite"),
    "restitution": (lambda d: d["contact"].update(restitution=1.5), r"contact\.restitution = 1\.5.*\[-1, 1\]"),
    "friction": (lambda d: d["contact"].update(friction=-0.1), r"contact\.friction = -0\.1.*>= 0"),
    "nan": (lambda d: d["vehicles"][1].update(speed=float("nan")), r"vehicles\[1\]\.speed = nan.*finite"),
    "inf": (lambda d: d["vehicles"][0]["position"].__setitem__(0, float("inf")), r"vehicles\[0\]\.position\[0\].*finite"),
    "wrong dimension": (lambda d: d["vehicles"][0].update(length="3 kg"), r"vehicles\[0\]\.length = '3 kg'.*dimension"),
    "unknown unit": (lambda d: d["vehicles"][1].update(speed="30 zorks"), r"vehicles\[1\]\.speed = '30 zorks'.*unknown unit"),
    "missing field": (lambda d: d["vehicles"][0].pop("width"), r"vehicles\[0\]\.width: missing field"),
    "missing restitution": (lambda d: d["contact"].pop("restitution"), r"contact\.restitution: missing field"),
    "one vehicle": (lambda d: d["vehicles"].pop(), r"exactly two vehicles"),
    "three vehicles": (lambda d: d["vehicles"].append(copy.deepcopy(d["vehicles"][0])), r"exactly two vehicles"),
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
    assert code == 2 and "exactly two vehicles" in err
    path = tmp_path / "broken.json"
    path.write_text("{not json")
    code, _, err = run_cli(capsys, "solve", str(path))
    assert code == 2 and "cannot be read" in err
    code, _, err = run_cli(capsys, "solve", str(tmp_path / "missing.json"))
    assert code == 2 and "no such file" in err


def test_bad_options_and_files_are_refused_before_solving(tmp_path, capsys):
    path = tmp_path / "c.json"
    path.write_text(json.dumps(US_CASE))
    for value in ("2", "-0.1", "nan", "x"):
        with pytest.raises(SystemExit) as exc:  # argparse: usage error, exit status 2
            main(["solve", str(path), "--smoothing", value])
        assert exc.value.code == 2 and "smoothing" in capsys.readouterr().err
    code, out, err = run_cli(capsys, "solve", str(path), "--plot", str(tmp_path / "top.xyz"))
    assert code == 2 and out == "" and "unknown picture type '.xyz' (use .png, .pdf or .svg)" in err
    binary = tmp_path / "latin1.json"
    binary.write_bytes(b'{"name": "caf\xe9"}')
    code, _, err = run_cli(capsys, "solve", str(binary))
    assert code == 2 and "not a UTF-8 text file" in err
    bom = tmp_path / "bom.json"  # as some editors write UTF-8: with a byte-order mark
    bom.write_bytes(b"\xef\xbb\xbf" + json.dumps(US_CASE).encode())
    assert run_cli(capsys, "solve", str(bom), "--json")[0] == 0


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


def test_overflowing_case_is_reported_not_drawn_with_nan(tmp_path, capsys):
    d = copy.deepcopy(US_CASE)
    d["vehicles"][1]["speed"] = 1e300  # m/s: finite, but its energy is not
    path = tmp_path / "huge.json"
    path.write_text(json.dumps(d))
    code, out, err = run_cli(capsys, "solve", str(path), "--plot", str(tmp_path / "huge.png"))
    assert code == 1 and "status: invalid: the results overflow" in out and "undefined" not in out
    assert "not solved" in err and (tmp_path / "huge.png").read_bytes()[:4] == b"\x89PNG"
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    status = "invalid: the results overflow (an input is far out of scale, e.g. a speed of 1e200 m/s or a mass of 1e-300 kg)"
    named = "; the input farthest out of scale: vehicles[1].speed = 1e+300 m/s"
    assert json.loads(out)["cases"][0] == {"name": "units check", "vehicles": [], "contact": {"status": status + named}}
    # the input named is the one out of scale, not survey coordinates: a weight of 1e-300 lbf is
    # 1e-300 * 0.45359237 kg, in a scene moved 300 km east and north
    far = copy.deepcopy(US_CASE)
    far["vehicles"][0]["weight"] = "1e-300 lbf"
    for v in far["vehicles"]:
        v["position"] = [f"{300000 + 0.3048 * float(x.split()[0])} m" for x in v["position"]]
    far["contact"]["point"] = [f"{300000 + 0.3048 * float(x.split()[0])} m" for x in far["contact"]["point"][:2]] + \
        [far["contact"]["point"][2]]
    path.write_text(json.dumps({"cases": [far, US_CASE]}))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    far_res, good = json.loads(out)["cases"]
    assert code == 1 and good["contact"]["status"] == "ok"
    assert far_res["contact"]["status"] == status + "; the input farthest out of scale: vehicles[0].mass = 4.5359e-301 kg"


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

    from ks_jax.derived import ees_pair

    e1, e2 = ees_pair(jnp.float64(2e4), jnp.float64(2.2e-16), jnp.float64(0.0), 1500.0, 1400.0, 9.0)
    assert np.isnan(e1) and np.isnan(e2)
    # a real crush splits the energy in proportion (MODEL.md section 4): E_i = E C_i / (C_1 + C_2)
    e1, e2 = ees_pair(jnp.float64(2e4), jnp.float64(0.3), jnp.float64(0.1), 1500.0, 1400.0, 9.0)
    assert float(e1) == pytest.approx(math.sqrt(2 * 2e4 * 0.75 / 1500.0), rel=1e-12)
    assert float(e2) == pytest.approx(math.sqrt(2 * 2e4 * 0.25 / 1400.0), rel=1e-12)


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


# runs the command line and reports on stderr how many programs it loaded from the persistent
# compile cache and how many it wrote there (JAX's events "cache_hits" and "cache_misses"; the
# latter is recorded only when an entry is written). Every program is stored, however quickly it
# compiled, so that one compiling near the command line's 0.5 s threshold cannot make the counts differ.
_COUNT_CACHE_HITS = """
import collections, json, sys, jax
from ks_jax import cli
setup = cli._compilation_cache
def store_all():
    setup()
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
cli._compilation_cache = store_all
seen, traced = collections.Counter(), set()
jax.monitoring.register_event_listener(lambda event, **_: seen.update([event.rsplit("/", 1)[-1]]))
def on_duration(event, duration, fun_name=None, **_):
    if event.endswith("jaxpr_trace_duration"):
        traced.add(fun_name)
jax.monitoring.register_event_duration_secs_listener(on_duration)
code = cli.main(sys.argv[1:])
print(json.dumps({"loaded": seen["cache_hits"], "written": seen["cache_misses"], "traced": sorted(traced)}),
      file=sys.stderr)
sys.exit(code)
"""


def test_compile_cache_is_used_and_kept_apart(tmp_path):
    """KS_JAX_CACHE=DIR: the first run stores its compiled programs there and a second run loads
    them (JAX's own cache-hit events) and gives the same report; so with pint's parsed unit definitions
    (the folder ``units``, written once) and with the programs as traced (``ks_jax.stored``: the second run
    traces none of ``solve``'s functions, and its report is the one of jax.jit's programs, KS_JAX_CACHE=off);
    nothing outside DIR is written, and KS_JAX_CACHE=off stores and loads nothing."""
    case = Path(ks_jax.__file__).parent / "cases" / "seed_000_saturn_pontiac.json"
    cache, off_home = tmp_path / "cache", tmp_path / "home"

    def run(where):
        env = dict(os.environ, KS_JAX_CACHE=str(where), XDG_CACHE_HOME=str(off_home))
        done = subprocess.run([sys.executable, "-c", _COUNT_CACHE_HITS, "solve", str(case), "--json"],
                              env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout), json.loads(done.stderr.strip().splitlines()[-1])

    first, counts = run(cache)
    written = counts.pop("written")
    assert counts.pop("loaded") == 0 and written > 0
    assert "flat" in counts["traced"]  # ks_jax.stored's export of a program
    entries = [p.name for p in cache.iterdir()]
    assert "units" in entries and any((cache / "units").iterdir())  # pint's definitions, parsed
    assert all(_CACHE_ENTRY.fullmatch(name) for name in entries if name != "units")
    assert any(name.endswith("-export") for name in entries) and any(name.endswith("-cache") for name in entries)
    kept = {p.name: p.stat().st_mtime_ns for p in (cache / "units").iterdir()}
    again, counts = run(cache)
    assert again == first
    assert counts.pop("loaded") == written and counts.pop("written") == 0  # every program it stored, loaded
    assert not {"flat", "_solve_explicit", "solve_inputs"} & set(counts["traced"]), counts["traced"]
    assert sorted(p.name for p in cache.iterdir()) == sorted(entries)
    assert {p.name: p.stat().st_mtime_ns for p in (cache / "units").iterdir()} == kept  # read, not written again
    off, counts = run("off")
    assert off == first
    assert counts["loaded"] == 0 and counts["written"] == 0 and "_solve_explicit" in counts["traced"]
    assert not off_home.exists()


def test_prune_cache_drops_least_recently_used_entries_only(tmp_path):
    names = [f"jit_solve_fn-{k:064x}-cache" for k in range(5)]
    names[1] = f"ks_jax__solve_explicit-{1:064x}-export"  # a program of ks_jax.stored: counted alike
    for age, name in enumerate(names):  # names[0] used last, names[4] first
        (tmp_path / name).write_bytes(b"x" * 1000)
        os.utime(tmp_path / name, (1e9 - 100 * age, 1e9 - 100 * age))
    other = tmp_path / "notes-cache"  # not a name JAX gives an entry: never counted or deleted
    other.write_bytes(b"y" * 10_000)
    os.utime(other, (1.0, 1.0))

    assert prune_cache(tmp_path, 5000) == 0
    assert prune_cache(tmp_path, 2500) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names[:2] + ["notes-cache"])
    assert prune_cache(tmp_path, 0) == 2
    assert [p.name for p in tmp_path.iterdir()] == ["notes-cache"]


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


def test_pictures_and_files_in_a_missing_folder_are_refused_before_solving(tmp_path, capsys):
    path = tmp_path / "c.json"
    path.write_text(json.dumps(US_CASE))
    a_file = tmp_path / "a.csv"
    a_file.write_text("x\n")
    for target, why in ((tmp_path / "nowhere" / "p.png", "does not exist"), (a_file / "p.png", "is a file")):
        code, out, err = run_cli(capsys, "solve", str(path), "--plot", str(target))
        assert code == 2 and out == "" and f"--plot {target}: the folder '{target.parent}' {why}" in err
        code, out, err = run_cli(capsys, "sweep", str(path), "--over", "contact.restitution=0:0.2:3",
                                 "--out", str(target.with_suffix(".csv")))
        assert code == 2 and out == "" and f"--out {target.with_suffix('.csv')}: the folder" in err
        assert "Traceback" not in err and "partial" not in err
    code, _, err = run_cli(capsys, "sweep", str(path), "--over", "contact.restitution=0:0.2:3", "--out", str(tmp_path))
    assert code == 2 and "unknown file type" in err
    for argv in (["sweep", str(path), "--over", "contact.restitution=uniform:0:0.2", "--samples", "3", "--seed", "-1",
                  "--out", str(tmp_path / "r.csv")], ["fit", str(path), "--seed", "-1"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2 and "a seed must be 0 or more" in capsys.readouterr().err


HEAD_ON = {
    "name": "head-on, inline",
    "vehicles": [
        {"mass": 1500, "inertia": [500, 2000, 2200], "length": 4.5, "width": 1.8, "height": 1.4, "cg_to_front": 2.25,
         "cg_height": 0.5, "position": [0, 0], "yaw": 0, "speed": 10},
        {"mass": 1800, "inertia": [600, 2400, 2600], "length": 4.5, "width": 1.8, "height": 1.4, "cg_to_front": 2.25,
         "cg_height": 0.5, "position": [4.5, 0], "yaw": 180, "speed": 10}],
    "contact": {"point": [2.25, 0, 0.5], "normal": 180, "restitution": 0.1, "friction": 0.5},
}


def test_a_vehicle_brought_to_rest_has_no_course_after(tmp_path, capsys):
    """Inline head-on, so the stick impulse (MODEL.md section 3, step 6): v' = vc (1 + eps) - eps v with
    vc = (1500 * 10 - 1800 * 10) / 3300 = -10/11 m/s. Vehicle 2 ends at 0 m/s: at rest, it has no course
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
    """MODEL.md section 4: directions in [0, 360), so 359.97 shown to one digit is 0.0, not 360.0; and the
    clock is the nearest hour, a half hour going clockwise (15 deg is 1 o'clock, as 45 deg is 2)."""
    import jax.numpy as jnp

    from ks_jax.derived import clock
    from ks_jax.report import _deg

    assert [_deg(x) for x in (359.97, 359.94, 0.04, 180.0, -0.01)] == ["0.0", "359.9", "0.0", "180.0", "0.0"]
    pdof = [0.0, 14.99, 15.0, 45.0, 75.0, 135.0, 165.0, 255.0, 315.0, 344.99, 345.0, 359.99]
    assert clock(jnp.array(pdof)).tolist() == [12, 12, 1, 2, 3, 5, 6, 9, 11, 11, 12, 12]


def test_ees_note_names_zero_crushes_when_they_are_rounding(tmp_path, capsys):
    """The shipped T-bone with no depth of penetration: the centroid lies on the boxes' faces, crushes of
    rounding size, EES undefined because both crushes count as 0 (derived.ees_pair), not because the
    (positive) energy loss were negative."""
    d = json.loads((Path(ks_jax.__file__).parent / "cases" / "auto_tbone.json").read_text())
    d["contact"]["penetration_time"] = "0 s"
    path = tmp_path / "touch.json"
    path.write_text(json.dumps(d))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    r = json.loads(out)["cases"][0]
    assert r["contact"]["energy_loss"] > 0 and all(v["ees"] is None and v["crush"] < 1e-9 for v in r["vehicles"])
    code, out, _ = run_cli(capsys, "solve", str(path))
    assert "both crushes are 0" in out and "negative" not in out
