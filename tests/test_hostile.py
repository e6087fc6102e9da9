"""What users and files can throw at ks-jax, and what it does: a clear message naming the case, the field, the
value and the rule, the documented exit status, no traceback, the other cases kept, and no silent wrong answer.

- an integer too long for a float (400 and 5000 digits) refuses its case, not the file;
- lists nested 100000 deep, and 40 deep, are refused, as is a file that never ends (/dev/zero) or is too large;
- a file of more cases than the limit is refused with the limit;
- an output folder that cannot be written is refused before any work;
- --samples, --starts and --monte-carlo beyond the machine's memory are refused up front;
- a friction of 1e308 is a friction large enough to stick, as 100 is;
- an orientation of 1e20 deg is 280 deg; 1e20 rad, 1e999 deg, a solid angle (30 sr) and a sweep over 1e21 deg
  are refused;
- "21 mhp", "30 kgs" and "90°" get a suggestion;
- a case name with terminal escape sequences prints them escaped;
- evidence, sigmas and bounds of 1e300 or 1e-300 are refused naming the evidence or the bound, and evidence
  named by a number, a list or nothing, as not a path;
- a denormal moment of inertia (1e-320) is refused where the file is read, with its value;
- a fit whose bounds never give a collision exits 1;
- a stopped sweep keeps its finished points, whole, in a file saying it is incomplete (.csv, .npz, .parquet);
- every field of the shipped cases, given any of a list of hostile values, is read or refused by name;
- a name that is not text, and a field given twice in one object, refuse their case, naming the field;
- values are quoted as the file wrote them (null, true, a TOML date), not as Python writes them;
- evidence named by a path of no form, and a --case that picks a refused case, say which case;
- State.create refuses a negative speed (turn the course instead), and the constructors a list or None where one
  number belongs, naming the argument; under jit, vmap and grad they give the numbers they gave before;
- from Python, an argument of another kind than an entry point takes (a dict to load_case, a chunk of "a", a
  sweep's outputs of 5, a Case for its inputs, a Solution for its result, an array to status_text, None to
  sweep_view) is refused, saying what it takes;
- a posterior's corner plot of draws with a NaN or an inf draws the finite ones and says how many it left out.
"""

from __future__ import annotations

import copy
import json
import math
import os
import subprocess
import sys
import re
import tomllib
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fit
import fit.spec
import ks_jax
from fit.synthetic import oblique_case
from ks_jax import units as U
from ks_jax.case import CaseError, case_from_dict, load_cases
from ks_jax.case import load as load_module
from ks_jax.sweeps.files import ResultWriter
from samples import CASES, SEED0, SEED1, mass_sweep, read_table, run_cli

FIT_CASE = CASES / "fit_seed_001.json"


def seed0():
    return json.loads(SEED0.read_text())


def written(tmp_path, name, data):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def test_an_integer_too_long_for_a_float_refuses_its_case_only(tmp_path):
    cases = []
    for k in range(6):
        d = seed0()
        d["name"] = f"case {k}"
        cases.append(d)
    cases[2]["vehicles"][0]["weight"] = "@400@"
    cases[4]["vehicles"][1]["weight"] = "@5000@"
    text = json.dumps({"cases": cases}).replace('"@400@"', "1" * 400).replace('"@5000@"', "-" + "9" * 5000)
    loaded = load_cases(written(tmp_path, "six.json", text))
    assert [c.valid for c in loaded] == [True, True, False, True, False, True]
    assert "vehicles[0].weight" in loaded[2].error and "about 400 digits" in loaded[2].error
    assert "vehicles[1].weight = -9999" in loaded[4].error and "an integer of 5000 digits" in loaded[4].error
    assert all(len(c.error) < 400 for c in loaded if not c.valid)  # the value is shown cut, not in full


def test_lists_nested_too_deep_and_files_too_large_are_refused(tmp_path):
    with pytest.raises(CaseError, match="nested too deep to read"):
        load_cases(written(tmp_path, "deep.json", "[" * 100_000 + "]" * 100_000))
    deep = '{"name": "x", "vehicles": ' + "[" * 40 + "]" * 40 + ', "contact": {}}'
    with pytest.raises(CaseError, match="nested more than 32 deep"):
        load_cases(written(tmp_path, "deep40.json", deep))
    big = tmp_path / "big.json"
    with big.open("wb") as f:  # a sparse file one byte over the limit
        f.truncate(load_module.MAX_FILE_BYTES + 1)
    with pytest.raises(CaseError, match="larger than 64 MiB, the limit of a case file"):
        load_cases(big)
    if os.path.exists("/dev/zero"):
        with pytest.raises(CaseError, match="larger than 64 MiB"):
            load_cases("/dev/zero")


def test_a_file_of_more_cases_than_the_limit_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(load_module, "MAX_CASES", 3)
    with pytest.raises(CaseError, match="4 cases, more than the 3 of a case file"):
        load_cases(written(tmp_path, "many.json", {"cases": [seed0()] * 4}))


def test_an_output_folder_that_cannot_be_written_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(ks_jax.files.tempfile, "NamedTemporaryFile", refuse)  # as a read-only folder does
    code, out, err = run_cli(capsys, "sweep", str(SEED1), "--over", "vehicles[1].speed=1:2:3", "--out",
                             str(tmp_path / "x.csv"))
    assert code == 2 and out == "" and "cannot write in the folder" in err and "Permission denied" in err
    code, out, err = run_cli(capsys, "solve", str(SEED1), "--plot", str(tmp_path / "x.png"))
    assert code == 2 and out == "" and "--plot" in err and "cannot write in the folder" in err


def test_samples_beyond_the_machine_memory_are_refused_up_front(tmp_path, capsys):
    code, _, err = run_cli(capsys, "sweep", str(SEED1), "--over", "vehicles[1].speed=uniform:10:20",
                           "--samples", str(10**12), "--out", str(tmp_path / "x.csv"))
    assert code == 2 and "--samples 1000000000000" in err and "GiB, more than this machine's" in err
    assert not list(tmp_path.iterdir())


def test_starts_and_refits_beyond_the_machine_memory_are_refused_up_front(capsys):
    code, _, err = run_cli(capsys, "fit", str(FIT_CASE), "--starts", str(10**8))
    assert code == 2 and "1 case(s) x 100000000 starts needs" in err and "give fewer starts" in err
    code, _, err = run_cli(capsys, "fit", str(FIT_CASE), "--monte-carlo", str(10**12))
    assert code == 2 and "--monte-carlo 1000000000000 x 8 starts needs" in err and "Traceback" not in err


def test_a_friction_beyond_any_real_value_sticks_as_a_large_one():
    """1e308: mu N would overflow; it must give what any friction large enough to stick gives."""
    d = oblique_case(np.random.default_rng(3))
    results = []
    for mu in (100.0, 1e308):
        e = copy.deepcopy(d)
        e["contact"]["friction"] = mu
        results.append(ks_jax.solve([case_from_dict(e)])[0].result)
    stick, huge = results
    assert not bool(stick.contact.sliding) and not bool(huge.contact.sliding)
    for a, b in ((stick.contact.impulse, huge.contact.impulse),
                 (stick.vehicles[0].yaw_rate_after, huge.vehicles[0].yaw_rate_after)):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-12, atol=1e-12)


def test_orientations_reduce_exactly_or_are_refused():
    def yaw(value):
        d = seed0()
        d["vehicles"][0]["yaw"] = value
        return float(case_from_dict(d).inputs.vehicles[0].yaw)

    # 10^20 = 280 (mod 360), exactly: 10^20 is 0 mod 8 and 10 mod 45
    assert yaw(1e20) == yaw("1e20 deg") == 280.0 * U.DEG
    assert yaw(720) == 0.0 and yaw("-400 deg") == -40.0 * U.DEG and yaw(30) == 30 * U.DEG
    assert math.isclose(yaw("2 rad"), 2.0, rel_tol=1e-15)
    with pytest.raises(CaseError, match=r"vehicles\[0\]\.yaw = '1e20 rad'.*turns"):
        yaw("1e20 rad")
    with pytest.raises(CaseError, match="an angle needs a plane-angle unit.*'sr' is not one"):
        yaw("30 sr")
    with pytest.raises(CaseError, match=r"vehicles\[0\]\.yaw = '1e999': must be a finite number"):
        yaw("1e999")
    with pytest.raises(CaseError, match="2.78e\\+18 turns.*at most 1e\\+06 turns"):  # a sweep's angles alike
        ks_jax.sweep(ks_jax.load_case(SEED0), {"vehicles[1].yaw": [0.0, math.radians(1e21)]})


def test_units_that_look_wrong_get_a_suggestion():
    with pytest.raises(U.UnitError, match="did you mean '21 mph'"):
        U.parse_quantity("21 mhp", "velocity")
    with pytest.raises(U.UnitError, match="did you mean '30 kg'"):
        U.parse_quantity("30 kgs", "mass")
    with pytest.raises(U.UnitError, match="write the degree sign as deg: '90 deg'"):
        U.parse_quantity("90°", "angle")


NAMES = ["Crash \u202eevil\u202c", "Kia\x1b]0;retitled\x07\x1b[2J K5\nforged line", "nul\x00byte\r", "tab\there \ud800"]
# the same names as a terminal shows them, written out by hand: each character that is not printable as its escape
SHOWN = ["Crash \\u202eevil\\u202c", "Kia\\x1b]0;retitled\\x07\\x1b[2J K5\\nforged line", "nul\\x00byte\\r",
         "tab\\there \\ud800"]


def _terminal_safe(text):
    """Nothing a terminal acts on: every character printable, or a line break."""
    return all(c.isprintable() or c == "\n" for c in text)


@pytest.mark.slow
def test_names_are_kept_exactly_and_shown_escaped(tmp_path, capsys):
    """A name with a bidirectional override, terminal escapes, a line break, NUL or a lone surrogate: the case
    keeps it exactly, ``solve --json`` carries it exactly (case and vehicle names, and a bad case's), and the
    panel and stderr show it escaped, with no character a terminal would act on."""
    cases = []
    for k, name in enumerate(NAMES):
        d = tomllib.loads(SEED1.read_text())
        d["name"] = name
        d["vehicles"][1]["name"] = name + " 2"
        cases.append(d)
    bad = copy.deepcopy(cases[0])
    bad["name"], bad["contact"]["restitution"] = NAMES[1], 5
    path = tmp_path / "names.json"
    path.write_bytes(json.dumps({"cases": cases + [bad]}).encode())  # ensure_ascii: the file holds \u escapes
    loaded = load_cases(path)
    assert [c.name for c in loaded] == NAMES + [NAMES[1]]
    assert [c.vehicle_names[1] for c in loaded[:-1]] == [n + " 2" for n in NAMES]
    code, out, err = run_cli(capsys, "solve", str(path), "--json")
    assert code == 1
    res = json.loads(out)["cases"]
    assert [r["name"] for r in res] == NAMES + [NAMES[1]]
    assert [r["vehicles"][1]["name"] for r in res[:-1]] == [n + " 2" for n in NAMES]
    assert res[-1]["contact"]["status"].startswith("invalid: ")
    assert _terminal_safe(out) and _terminal_safe(err)
    assert f"case '{SHOWN[1]}' not solved" in err and f"case '{SHOWN[1]}': contact.restitution = 5" in err
    code, out, err = run_cli(capsys, "solve", str(path))
    assert code == 1 and _terminal_safe(out) and _terminal_safe(err)
    for shown in SHOWN:
        assert f"Case: {shown}\n" in out and f"vehicles[1]: {shown} 2\n" in out
    # one case alone, refused: the error on stderr names it escaped
    alone = tmp_path / "alone.json"
    alone.write_text(json.dumps(bad))
    code, out, err = run_cli(capsys, "solve", str(alone))
    assert code == 2 and out == "" and _terminal_safe(err) and f"case '{SHOWN[1]}': contact.restitution" in err


@pytest.mark.slow
def test_a_fit_carries_names_exactly_in_json_and_escaped_in_text(tmp_path, capsys):
    d = json.loads(FIT_CASE.read_text())
    d["name"] = NAMES[0] + NAMES[1]
    path = written(tmp_path, "named.json", d)
    code, out, err = run_cli(capsys, "fit", str(path), "--json", "--starts", "1", "--max-starts", "1")
    assert code in (0, 1) and _terminal_safe(err)
    assert json.loads(out)["cases"][0]["name"] == NAMES[0] + NAMES[1]
    code, out, err = run_cli(capsys, "fit", str(path), "--starts", "1", "--max-starts", "1")
    assert _terminal_safe(out) and _terminal_safe(err) and f"Reconstruction: {SHOWN[0]}{SHOWN[1]}\n" in out


@pytest.mark.slow
def test_pictures_of_a_fit_and_a_sweep_draw_names_as_their_escapes(tmp_path, capsys):
    """The top view at the estimate, the posterior's corner plot and a sweep's figure of a case and a vehicle
    named with escape sequences and a direction override: every one is drawn with no glyph missing
    (matplotlib warns of one it cannot draw: an error here), so nothing the name holds reaches the picture raw."""
    d = json.loads(FIT_CASE.read_text())
    d["name"], d["vehicles"][1]["name"] = NAMES[0], NAMES[1]
    path = written(tmp_path, "named.json", d)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        # the commands and values of tests/command_matrix.py on the same case: the programs it compiled are loaded
        code, _, err = run_cli(capsys, "fit", str(path), "--posterior", "6", "--chains", "2", "--json",
                               "--plot", str(tmp_path / "fit.png"))
        assert code in (0, 1) and "Traceback" not in err
        code, _, err = run_cli(capsys, "sweep", str(path), "--case", "0", "--over", mass_sweep(ks_jax.load_case(path)),
                               "--out", str(tmp_path / "s.csv"), "--plot", str(tmp_path / "s.png"), "--no-progress")
        assert code == 0, err
    assert all((tmp_path / f).stat().st_size > 0 for f in ("fit.png", "fit_posterior.png", "s.png"))


@pytest.mark.parametrize("where, value, message", [
    ("value", 1e300, r"evidence: vehicles\[0\]\.delta_v_magnitude: value .*1e\+300 m/s\): beyond 1e\+12"),
    ("sigma", 1e300, r"evidence: vehicles\[0\]\.delta_v_magnitude: sigma = .*1e\+300 m/s\): must be within"),
    ("sigma", 1e-300, r"evidence: vehicles\[0\]\.delta_v_magnitude: sigma = 1e-300 \(SI\): must be within"),
    ("bound", 1e300, r"unknowns: vehicles\[1\]\.speed: upper bound .*1e\+300 m/s\): beyond 1e\+12"),
])
def test_evidence_and_bounds_beyond_computing_are_refused_by_name(where, value, message):
    case = ks_jax.load_case(FIT_CASE)
    evidence = copy.deepcopy(case.raw["evidence"])
    unknowns = copy.deepcopy(case.raw["unknowns"])
    if where == "bound":
        unknowns["vehicles[1].speed"]["bounds"] = [0, value]
    else:
        evidence[0][where] = value
    with pytest.raises(CaseError, match=message):
        fit.reconstruct(case, unknowns, evidence)


def test_evidence_named_by_something_other_than_a_path_is_refused():
    case = ks_jax.load_case(FIT_CASE)
    for quantity, message in ((0, "a path is a string"), (1.5, "a path is a string"), (None, "needs quantity"),
                              (["vehicles[0].delta_v_magnitude"], "a path is a string"),
                              ({"a": 1}, "a path is a string")):
        evidence = copy.deepcopy(case.raw["evidence"])
        evidence[0]["quantity"] = quantity
        with pytest.raises(CaseError, match=message):
            fit.reconstruct(case, case.raw["unknowns"], evidence)


def test_a_denormal_moment_of_inertia_is_refused_where_the_file_is_read():
    d = seed0()
    d["vehicles"][1]["inertia"] = [1e-320, 2000, 2000]
    with pytest.raises(CaseError, match=r"vehicles\[1\]\.inertia\[0\] = 1e-320: must be at least 0\.001 kg m\^2"):
        case_from_dict(d)
    d["vehicles"][1]["inertia"] = [[1e-320, 0, 0], [0, 2000, 0], [0, 0, 2000]]
    with pytest.raises(CaseError, match=r"vehicles\[1\]\.inertia = .*must be at least 0\.001"):
        case_from_dict(d)


@pytest.mark.slow
def test_a_fit_whose_bounds_never_give_a_collision_exits_1(tmp_path, capsys):
    d = json.loads(FIT_CASE.read_text())
    d["unknowns"]["vehicles[1].speed"]["bounds"] = ["0 mph", "0.001 mph"]  # the Kia never reaches the Lucid
    code, out, err = run_cli(capsys, "fit", str(written(tmp_path, "never.json", d)))
    assert code == 1 and "Traceback" not in err
    assert "the fit did not converge" in err or "ended where the exchange is" in err


@pytest.mark.parametrize("suffix", [".csv", ".npz", ".parquet"])
def test_a_stopped_sweep_keeps_its_finished_points_whole(tmp_path, suffix):
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    axes = {"vehicles[1].speed": np.linspace(1.0, 10.0, 10), "contact.restitution": np.linspace(0.0, 0.5, 6)}
    out = tmp_path / f"out{suffix}"
    writer = ResultWriter(out, axes, "grid", (10, 6))

    def chunk(lo, hi):
        return {"contact.impulse_magnitude": np.arange(lo, hi, dtype=float), "status": np.zeros(hi - lo, np.int8)}

    writer.chunk(0, 24, chunk(0, 24))
    writer.chunk(24, 48, chunk(24, 48))
    kept, rows = writer.keep_incomplete()
    assert kept == tmp_path / f"out.incomplete{suffix}" and rows == 48
    assert sorted(p.name for p in tmp_path.iterdir()) == [kept.name]  # the unfinished file became it; no out
    if suffix == ".npz":
        with np.load(kept) as z:
            np.testing.assert_array_equal(z["contact.impulse_magnitude"], np.arange(48.0))
            np.testing.assert_array_equal(z["flat_index"], np.arange(48))
    else:
        table = read_table(kept)
        np.testing.assert_array_equal(table["contact.impulse_magnitude"], np.arange(48.0))
        np.testing.assert_allclose(table["contact.restitution"][:6], np.linspace(0.0, 0.5, 6))
    nothing = ResultWriter(tmp_path / f"none{suffix}", axes, "grid", (10, 6))
    assert nothing.keep_incomplete() == (None, 0)


HOSTILE_VALUES = [None, True, "", " ", "abc", "nan", "inf", "-inf", "1e999", "-0", 0, -1, 1e-320, 1e308, -1e308, [],
                  [1], [1, 2, 3, 4], {}, {"a": 1}, "12 parsecs", "5 mph mph", "1/0 m", "3 m/s^-1", "\u202e12", "1_000",
                  [[1, 2], [3]], ["1 m", None], "0x10", "\u0661\u0662", "1e5 kg*m^2/s", "10 deg/s/s", "30 sr"]


def _leaves(d, prefix=()):
    """The paths of a case dict's values (into vehicles by index), names and free text left out."""
    if isinstance(d, dict):
        for k, v in d.items():
            if k not in ("name", "description", "reference"):
                yield from _leaves(v, prefix + (k,))
    elif isinstance(d, list) and d and isinstance(d[0], dict):
        for i, v in enumerate(d):
            yield from _leaves(v, prefix + (i,))
    else:
        yield prefix


@pytest.mark.slow
def test_every_field_of_a_case_with_any_hostile_value_is_read_or_refused():
    """Each value of the shipped seed case and fit case replaced by each of ``HOSTILE_VALUES``: the case is read,
    or refused with a CaseError naming the field; nothing else is raised, and what is read is finite."""
    for source in (SEED0, FIT_CASE):
        base = json.loads(source.read_text())
        for path in _leaves(base):
            for value in HOSTILE_VALUES:
                d = copy.deepcopy(base)
                holder = d
                for key in path[:-1]:
                    holder = holder[key]
                holder[path[-1]] = value
                try:
                    case = case_from_dict(d)
                except CaseError as err:
                    assert path[-1] in str(err) or "unknowns" in path or "evidence" in path, (path, value, err)
                    continue
                leaves = [np.asarray(x, float) for x in jax.tree_util.tree_leaves(case.inputs)]
                assert all(np.all(np.isfinite(x)) for x in leaves), (path, value)
                if "unknowns" in d:
                    try:
                        fit.spec.parse_unknowns(case, d["unknowns"])
                        fit.spec.parse_evidence(case, d["evidence"])
                    except CaseError:
                        pass


def test_hostile_files_and_arguments_give_one_clear_error(tmp_path, capsys):
    """Files and arguments that are not a case or a sweep (empty, whitespace, a list, no vehicles, NaN and
    1e400 literals, a lone surrogate in a name, a value or an --over spec): every command says what and
    where on one line, exit status 2, and no traceback."""
    base = seed0()
    files = {
        "empty.json": ("", "the file is empty"), "blank.toml": ("  \n", "the file is empty"),
        "list.json": ("[]", "a case must be an object/table, got []"),
        "null.json": ("null", "a case must be an object/table, got null"),
        "none.json": (json.dumps({**base, "vehicles": []}), "vehicles: 0 given; a case has 1 to 8 vehicles"),
        "word.json": (json.dumps({**base, "vehicles": "two"}), "vehicles = 'two': not a list"),
        "nan.json": (json.dumps(base).replace('"yaw": 0', '"yaw": NaN', 1), "vehicles[0].yaw = nan: must be a finite"),
        "big.json": (json.dumps(base).replace('"yaw": 0', '"yaw": 1e400', 1),
                     "vehicles[0].yaw = inf: must be a finite"),
        "lone.json": ('{"name": "\\udcff", "vehicles": 3}', "case '\\udcff': vehicles = 3: not a list"),
    }
    for name, (text, message) in files.items():
        path = written(tmp_path, name, text)
        for argv in (["solve", str(path)], ["solve", str(path), "--json"], ["fit", str(path)],
                     ["sweep", str(path), "--over", "contact.restitution=0:0.1:2", "--out", str(tmp_path / "o.csv")]):
            code, out, err = run_cli(capsys, *argv)
            assert code == 2 and out == "" and "Traceback" not in err, (argv, err)
            assert err.startswith("ks-jax: error: ") and message in err and err.count("\n") == 1, (argv, err)
    for over, message in (("vehicles[1].speed=\udcff", "'\\udcff' is not a '<number> <unit>' quantity"),
                          ("vehicles[1].speed=0:1e400:3", "STOP = '1e400' must be a finite number"),
                          ("contact.restitution=0:1:1e30", "N = '1e30' must be a whole number")):
        code, out, err = run_cli(capsys, "sweep", str(SEED1), "--over", over, "--out", str(tmp_path / "o.csv"))
        assert code == 2 and out == "" and message in err and "Traceback" not in err, err
    assert not (tmp_path / "o.csv").exists()


def test_a_terminal_that_cannot_show_a_name_gets_its_escapes(tmp_path, capsys, monkeypatch):
    """On a terminal whose encoding is ASCII (LANG=C) a name such as 'Café' is written with its escape, not
    stopped by an encoding error."""
    import io
    import sys

    d = seed0()
    d["name"] = "Caf\u00e9 \u4e2d"
    path = written(tmp_path, "cafe.json", d)
    stdout = io.TextIOWrapper(io.BytesIO(), encoding="ascii")
    monkeypatch.setattr(sys, "stdout", stdout)
    code = ks_jax.cli.main(["solve", str(path)])
    stdout.flush()
    text = stdout.buffer.getvalue().decode("ascii")
    assert code == 0 and text.startswith("Case: Caf\\xe9 \\u4e2d\n")


def test_a_name_that_is_not_text_refuses_its_case_by_field():
    """A case's, a vehicle's or a fixed object's name must be text: written as text, 5, null or a list would not be
    the name the file gave. In a file of several cases the case is refused, under its default name ("case 2"), and
    the others are read."""
    base = seed0()
    wall = {"kind": "wall", "point": [30, 0], "normal": 180}
    bad = [({**base, "name": 5}, "case 'case 2': name = 5: a name must be text"),
           ({**base, "name": None}, "case 'case 2': name = null: a name must be text"),
           ({**base, "vehicles": [{**base["vehicles"][0], "name": ["a"]}, base["vehicles"][1]]},
            "vehicles[0].name = ['a']: a name must be text"),
           ({**base, "vehicles": base["vehicles"][:1], "fixed": [{**wall, "name": True}]},
            "fixed[0].name = true: a name must be text")]
    for case, message in bad:
        first, second = load_module.cases_from_data({"cases": [base, case]}, "file.json")
        assert first.valid and first.name == base["name"]
        assert not second.valid and message in second.error and second.name == (
            case["name"] if isinstance(case.get("name"), str) else "case 2"), second.error
    with pytest.raises(CaseError, match="case 'x': name = 3.5: a name must be text"):
        case_from_dict({**base, "name": 3.5}, "x")


def test_a_field_given_twice_in_one_object_refuses_its_case_with_both_values(tmp_path):
    """JSON's reader would keep the last of a field given twice (TOML's refuses the file): the case is refused,
    naming the field and both values, and the file's other cases are read; "cases" given twice refuses the file."""
    base = json.dumps(seed0())
    twice = base.replace('"speed": ', '"speed": "5 mph", "speed": ', 1)
    path = written(tmp_path, "twice.json", '{"cases": [' + base + ", " + twice + "]}")
    first, second = load_cases(path)
    assert first.valid and not second.valid
    assert "vehicles[0].speed: given 2 times in one object ('5 mph', " in second.error, second.error
    nested = base.replace('"contact": {', '"contact": {"friction": 0.3, ', 1)
    with pytest.raises(CaseError, match=r"contact\.friction: given 2 times in one object \(0\.3, "):
        load_cases(written(tmp_path, "nested.json", nested))
    with pytest.raises(CaseError, match='"cases" given 2 times'):
        load_cases(written(tmp_path, "files.json", '{"cases": [' + base + '], "cases": [' + base + "]}"))
    assert load_cases(written(tmp_path, "once.json", base))[0].valid


def test_values_are_quoted_as_the_file_wrote_them(tmp_path):
    """null, true and a TOML date in a number's place are quoted as the file wrote them, not as Python's None,
    True or datetime."""
    base = seed0()
    for value, words in ((None, "weight = null: null is not a number"), (True, "weight = true: true is not a"),
                         ([None, False], "weight = [null, false]: [null, false] is not a number")):
        vehicles = [{**base["vehicles"][0], "weight": value}, base["vehicles"][1]]
        with pytest.raises(CaseError, match=re.escape(words)):
            case_from_dict({**base, "vehicles": vehicles})
    toml = tomllib.loads("yaw = 1979-05-27T07:32:00Z\nat = 07:32:00")
    for key in ("yaw", "at"):
        vehicles = [{**base["vehicles"][0], "yaw": toml[key]}, base["vehicles"][1]]
        with pytest.raises(CaseError, match=re.escape("(a TOML date or time) is not a number")) as err:
            case_from_dict({**base, "vehicles": vehicles})
        assert "datetime" not in str(err.value)


def test_evidence_of_no_form_and_a_refused_case_chosen_by_index_say_which_case(tmp_path, capsys):
    """A path of no form as evidence is refused as evidence of its case; a sweep's --case that picks a refused
    case names the index and the file's own count of it."""
    case = ks_jax.load_case(FIT_CASE)
    for quantity in ("vehicles[0.5].delta_v_magnitude", "vehicles[-1].delta_v_magnitude"):
        evidence = copy.deepcopy(case.raw["evidence"])
        evidence[0]["quantity"] = quantity
        with pytest.raises(CaseError, match=re.escape(f"case '{case.name}': evidence: path '{quantity}'")):
            fit.reconstruct(case, case.raw["unknowns"], evidence)
    base = seed0()
    path = written(tmp_path, "two.json", {"cases": [base, {**base, "contact": 3}]})
    code, out, err = run_cli(capsys, "sweep", str(path), "--case", "1", "--over", "contact.restitution=0:0.1:2",
                             "--out", str(tmp_path / "o.csv"))
    assert code == 2 and err.startswith("ks-jax: error: --case 1 (the file's case 2): case '")
    assert "': contact: must be a table/object, got 3" in err


@pytest.mark.slow
def test_a_character_the_pictures_font_cannot_draw_is_one_line_of_the_command(tmp_path):
    """matplotlib warns of a glyph its font lacks with its own source lines, for every text that holds it: the
    command says it once, on one line, and draws the picture."""
    d = seed0()
    d["vehicles"][0]["name"] = "Car \N{AUTOMOBILE}"
    path = written(tmp_path, "car.json", d)
    env = {**os.environ, "PYTHONIOENCODING": "utf-8", "KS_JAX_CACHE": "off"}
    run = subprocess.run([sys.executable, "-m", "ks_jax.cli", "solve", str(path), "--plot", str(tmp_path / "t.png")],
                         capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    note = "ks-jax: note: the pictures' font has no glyph for \N{AUTOMOBILE} (U+1F697); it is drawn as a box"
    assert run.stderr.splitlines().count(note) == 1 and "UserWarning" not in run.stderr, run.stderr
    assert (tmp_path / "t.png").stat().st_size > 0


def test_the_python_api_refuses_what_it_cannot_use_by_name(tmp_path):
    """From Python: an output path of a vehicle the result has not, a sweep's results stored as integers, booleans
    or float16 (an invalid row's NaN would read as a number; a valid one would overflow), writing a sweep that kept
    nothing, a fit's counts that are not whole numbers, an Unknown or Evidence made with a unit string or an array,
    and a top view of nothing or of a Case: each refused with the argument, its value and the rule."""
    case = ks_jax.load_case(SEED1)
    solved = ks_jax.solve(case)
    with pytest.raises(CaseError, match=r"path 'vehicles\[2\]\.delta_v_magnitude': the result has no vehicles\[2\]"):
        ks_jax.get_output(solved.result, "vehicles[2].delta_v_magnitude")
    for dtype in (np.float16, np.int32, bool):
        with pytest.raises(CaseError, match="output_dtype = .*: must be float32 or float64"):
            ks_jax.sweep(case, {"vehicles[1].speed": [9.0, 10.0]}, output_dtype=dtype)
    nothing = ks_jax.sweep(case, {"vehicles[1].speed": [9.0, 10.0]}, outputs=["contact.energy_loss"], keep=False)
    with pytest.raises(CaseError, match="this sweep kept no results"):
        ks_jax.sweeps.write_results(nothing, tmp_path / "nothing.csv")
    assert not (tmp_path / "nothing.csv").exists()
    fitted = ks_jax.load_case(FIT_CASE)
    for kwargs, words in (({"monte_carlo": -1}, "monte_carlo = -1: must be a whole number >= 0"),
                          ({"starts": 2.5}, "starts = 2.5: must be a whole number >= 1"),
                          ({"max_iter": 0}, "max_iter = 0: must be a whole number >= 1"),
                          ({"rtol": -1.0}, r"rtol = -1.0: the relative singular-value threshold must be in \(0, 1\)"),
                          ({"target_acceptance": 1.0}, r"target_acceptance = 1.0: the posterior's mean acceptance "
                                                       r"must be in \(0, 1\)"),
                          ({"target_acceptance": math.nan}, r"target_acceptance = nan: .* must be in \(0, 1\)"),
                          ({"dtype": np.float16}, "dtype = .*float16.*: a fit computes in float32 or float64"),
                          ({"dtype": "int32"}, "dtype = 'int32': a fit computes in float32 or float64"),
                          ({"dtype": "single precision"}, "dtype = 'single precision': a fit computes in float32")):
        with pytest.raises(ValueError, match=words):
            fit.reconstruct(fitted, **kwargs)
    speed = "vehicles[1].speed"
    for unknown, evidence, words in (
            (fit.Unknown(speed, "0 mph", "60 mph"), None, r"lower = '0 mph': must be one number \(made in Python"),
            (fit.Unknown(speed, 0.0, 30.0, prior=(10.0,)), None, r"prior = \[10.0\]: must be \(mean, sigma\)"),
            (None, fit.Evidence(speed, np.array([2.9, 3.0]), 0.1), r"value = array\(\[2.9, 3. \]\): must be one"),
            (None, fit.Evidence(speed, math.inf, 0.1), "value inf must be finite")):
        with pytest.raises(CaseError, match=words):
            fit.reconstruct(fitted, [unknown or fit.Unknown(speed, 0.0, 30.0)],
                            [evidence or fit.Evidence(speed, 9.0, 0.1)])
    with pytest.raises(ValueError, match="no solution given"):
        ks_jax.plot.top_view_figure([])
    with pytest.raises(TypeError, match="a Solution from ks_jax.solve is drawn, not a Case"):
        ks_jax.plot.top_view(case)


def test_an_exchange_of_inputs_of_the_wrong_kind_or_shape_is_refused_by_name():
    """``exchange`` (alone or under ``jax.vmap``) and ``exchange_batch`` refuse an input of the wrong shape or kind,
    naming it, before any work: a mass of (1,) would broadcast over the row and give every result another shape and
    the status "results overflow", a position of (2,) or a list would fail deep inside."""
    car = ks_jax.Vehicle.create(1400.0, [500.0, 2000.0, 2200.0], 4.5, 1.8)
    state = ks_jax.State.create([0.0, 0.0, 0.5], 0.0, speed=10.0)
    other = ks_jax.State.create([-4.0, 0.5, 0.5], 0.0, speed=15.0)  # catching up: closing
    contact = ks_jax.Contact.create([-2.0, 0.2, 0.5], [1.0, 0.0, 0.0], 0.1, 0.5)
    for args, kind, words in (
            ((car._replace(mass=jnp.array([1400.0])), state, car, other, contact), ValueError,
             r"exchange: vehicle1\.mass has shape \(1,\); it must be \(\)"),
            ((car, state._replace(position=jnp.zeros(2)), car, other, contact), ValueError,
             r"state1\.position has shape \(2,\); it must be \(3,\)"),
            ((car, state, car, other, contact._replace(point=[0.0, 0.0, 0.5])), TypeError,
             r"contact\.point = \[0\.0, 0\.0, 0\.5\]: must be an array or a number"),
            ((state, state, car, other, contact), TypeError, "vehicle1 must be a Vehicle .* got a State")):
        with pytest.raises(kind, match=words):
            ks_jax.exchange(*args)
    rows = [jax.tree_util.tree_map(lambda x: np.stack([np.asarray(x)] * 2), a) for a in (car, state, car, other,
                                                                                           contact)]
    rows[1] = rows[1]._replace(position=np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"exchange_batch: state1\.position has shape \(2, 2\); it must be \(N, 3\)"):
        ks_jax.exchange_batch(*rows)
    assert np.asarray(ks_jax.exchange(car, state, car, other, contact).contact.status) == 0


def test_the_constructors_refuse_a_negative_speed_a_list_or_nothing_by_name_and_still_trace():
    """``State.create`` refuses a negative speed as a case file does (the course turned by pi is backwards travel;
    a velocity of -5 along the course was made without a word), a yaw rate of three numbers (it gave an angular
    velocity of shape (3, 3)); ``Vehicle.create`` a mass of None (an error from inside jnp.array) or of two numbers
    (a mass of shape (2,)). Under jax.vmap, jax.jit and jax.grad, where a value is traced, the same calls give the
    numbers they gave before: speed times the course's cosine and sine."""
    here = [1.0, 2.0, 0.5]
    with pytest.raises(ValueError, match=re.escape("State.create: speed = -5.0: speed must be >= 0 (reverse the "
                                                   "course for backwards travel: speed=5.0, course=yaw + pi)")):
        ks_jax.State.create(here, yaw=0.0, speed=-5.0)
    with pytest.raises(ValueError, match=r"State.create: yaw_rate has shape \(3,\): give one number, the rate about z "
                                         r"in rad/s; angular_velocity= takes \(wx, wy, wz\)"):
        ks_jax.State.create(here, speed=1.0, yaw_rate=[0.1, 0.2, 0.3])
    with pytest.raises(TypeError, match="Vehicle.create: mass = None: give one number, in kg"):
        ks_jax.Vehicle.create(mass=None, inertia=[1, 2, 3], length=1, width=1)
    with pytest.raises(ValueError, match=r"Vehicle.create: mass has shape \(2,\): give one number, in kg "
                                         r"\(Vehicle.create makes one row: for a batch, jax.vmap it\)"):
        ks_jax.Vehicle.create(mass=[1400.0, 1500.0], inertia=[500, 2000, 2200], length=4.5, width=1.8)
    speeds, yaw = np.array([-3.0, 0.0, 7.5]), 0.3  # traced: not seen as negative, and the same numbers as before
    want = np.stack([speeds * math.cos(yaw), speeds * math.sin(yaw), 0 * speeds], -1)
    states = jax.vmap(lambda v: ks_jax.State.create(here, yaw, speed=v, yaw_rate=v))(jnp.asarray(speeds))
    np.testing.assert_allclose(states.velocity, want, rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(states.angular_velocity, np.stack([0 * speeds, 0 * speeds, speeds], -1))
    np.testing.assert_allclose(jax.jit(lambda v: ks_jax.State.create(here, yaw, speed=v).velocity)(-3.0), want[0],
                               rtol=1e-15)
    assert float(jax.grad(lambda v: ks_jax.State.create(here, yaw, speed=v).velocity[0])(-3.0)) == pytest.approx(
        math.cos(yaw), rel=1e-15)
    mass = jax.vmap(lambda m: ks_jax.Vehicle.create(m, [500.0, 2000.0, 2200.0], 4.5, 1.8).mass)
    np.testing.assert_array_equal(mass(jnp.array([1400.0, 1500.0])), [1400.0, 1500.0])
    plain = ks_jax.State.create(here, yaw, speed=7.5)
    np.testing.assert_allclose(plain.velocity, want[2], rtol=1e-15)


def test_the_python_api_entry_points_say_what_they_take(tmp_path):
    """From Python, an argument of another kind than an entry point takes: a case as a dict to load_case (a pathlib
    TypeError), a chunk of "a" or 2.5 rows (int()'s ValueError, or 2 rows without a word), a sweep's outputs of 5 or
    on_chunk of 5 ("'int' object is not iterable", "not callable"), a Case to get_input, set_input or solve_inputs
    and a Solution to get_output (an AttributeError from inside), status codes as an array (int()'s "only
    0-dimensional arrays") or of 10.5 (read as 10), a sweep's picture of None (no attribute 'outputs'): each is
    refused naming the argument, its value or kind, and what to give."""
    with pytest.raises(TypeError, match=re.escape("load_case takes the path of a case file (a str or a pathlib.Path), "
                                                  "got a dict: a case given as a dict is read by "
                                                  "ks_jax.case.case_from_dict")):
        ks_jax.load_case({"vehicles": []})
    car = ks_jax.Vehicle.create(1400.0, [500.0, 2000.0, 2200.0], 4.5, 1.8)
    rows = [jax.tree_util.tree_map(lambda x: np.stack([np.asarray(x)] * 2), a) for a in (
        car, ks_jax.State.create([0.0, 0.0, 0.5], speed=10.0), car, ks_jax.State.create([-4.0, 0.5, 0.5], speed=15.0),
        ks_jax.Contact.create([-2.0, 0.2, 0.5], [1.0, 0.0, 0.0], 0.1, 0.5))]
    for chunk in ("a", 2.5):
        with pytest.raises(ValueError, match=re.escape(f"exchange_batch: chunk = {chunk!r}: chunk must be a positive "
                                                       "number of rows (a whole number >= 1)")):
            ks_jax.exchange_batch(*rows, chunk=chunk)
    assert np.all(ks_jax.exchange_batch(*rows, chunk=np.int64(1)).contact.status == 0)
    case, over = ks_jax.load_case(SEED1), {"vehicles[1].speed": [9.0]}
    with pytest.raises(CaseError, match=re.escape("sweep: outputs = 5: give output paths, a string or a list of "
                                                  "strings")):
        ks_jax.sweep(case, over, outputs=5)
    with pytest.raises(CaseError, match=re.escape("sweep: on_chunk = 5: must be a function, called as on_chunk(lo, "
                                                  "hi, chunk) for every chunk")):
        ks_jax.sweep(case, over, on_chunk=5)
    for call, name in ((lambda: ks_jax.get_input(case, "vehicles[1].speed"), "get_input"),
                       (lambda: ks_jax.set_input(case, "vehicles[1].speed", 9.0), "set_input"),
                       (lambda: ks_jax.solve_inputs(case), "solve_inputs")):
        with pytest.raises(TypeError, match=re.escape(f"{name} takes a case's inputs (case.inputs), got a Case")):
            call()
    solved = ks_jax.solve(case)
    with pytest.raises(TypeError, match=re.escape("get_output takes a result (an ExchangeResult: solution.result of a "
                                                  "Solution, or what solve_inputs and exchange return), got a "
                                                  "Solution")):
        ks_jax.get_output(solved, "contact.impulse_magnitude")
    assert float(ks_jax.get_output(solved.result, "contact.impulse_magnitude")) > 0  # what it takes: the result
    with pytest.raises(TypeError, match=re.escape("status_text takes one status code, got an array of shape (2,): "
                                                  "for the words of each, [ks_jax.status_text(c) for c in "
                                                  "codes.tolist()]")):
        ks_jax.status_text(np.array([0, 10]))
    for code in (10.5, math.nan, True):  # 10.5 read as 10: "an input is NaN or infinite"
        with pytest.raises(ValueError, match=re.escape(f"status_text: code = {code!r}: a status code is a whole "
                                                       "number")):
            ks_jax.status_text(code)
    assert ks_jax.status_text(np.int8(10)) == ks_jax.status_text(10.0) == "invalid: an input is NaN or infinite"
    for draw, given in ((ks_jax.plot.sweep_view, None), (ks_jax.plot.save_sweep_view, case)):
        with pytest.raises(TypeError, match=re.escape(f"{draw.__name__}: a sweep's result (the SweepResult of "
                                                      f"ks_jax.sweep) is drawn, not a {type(given).__name__}")):
            draw(given, tmp_path / "s.png") if given is case else draw(given)
    assert not (tmp_path / "s.png").exists()


def test_a_corner_plot_of_draws_with_nan_or_inf_draws_the_finite_ones_and_says_so():
    """A posterior's corner plot given draws with a NaN (dropped by matplotlib without a word) or an inf (a ValueError
    from numpy's histogram, no picture): the finite draws are drawn, as the plot of them alone is, and the legend
    says how many were left out; draws of which none is finite are refused."""
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    draws = np.random.default_rng(2).normal([20.0, 0.3], [0.5, 0.02], (600, 2))
    bad = draws.copy()
    bad[5, 1], bad[7, 0], bad[9] = np.nan, np.inf, -np.inf
    axes = ks_jax.plot.corner(Figure(), bad, ["a", "b"], [20.0, 0.3], np.diag([0.25, 4e-4]))
    alone = ks_jax.plot.corner(Figure(), draws[np.all(np.isfinite(bad), 1)], ["a", "b"], [20.0, 0.3],
                               np.diag([0.25, 4e-4]))
    for i in range(2):
        assert [p.get_height() for p in axes[i, i].patches] == [p.get_height() for p in alone[i, i].patches]
    assert len(axes[1, 0].lines[0].get_xdata()) == 597
    legend = [t.get_text() for t in axes[0, 0].get_legend().get_texts()]
    assert legend[0] == "posterior (NUTS)\n3 of 600 draws not finite\n(NaN or inf): left out", legend
    with pytest.raises(ValueError, match=re.escape("corner: none of the 600 draws is finite (each holds a NaN or an "
                                                   "inf): nothing to draw")):
        ks_jax.plot.corner(Figure(), np.where(np.arange(2) == 1, np.nan, bad), ["a", "b"])
