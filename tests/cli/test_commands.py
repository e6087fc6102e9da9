"""The command line: ``ks-jax solve`` (panel and JSON), ``ks-jax demo``, options and output files refused
before anything is solved."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

import ks_jax
from ks_jax import units as U
from ks_jax.case import load_case
from ks_jax.cli import main
from ks_jax.solve.crush import FIELDS as CRUSH_FIELDS
from samples import US_CASE, run_cli


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


def test_json_keys_are_model_section_4(tmp_path, capsys):
    path = tmp_path / "c.json"
    path.write_text(json.dumps(US_CASE))
    code, out, _ = run_cli(capsys, "solve", str(path), "--json")
    res = json.loads(out)["cases"][0]
    assert set(res) == {"name", "between", "contact", "vehicles", "exchanges", "energy_loss_total"}
    assert set(res["contact"]) == set(ks_jax.ContactResult._fields)
    assert set(res["vehicles"][0]) == set(ks_jax.VehicleResult._fields) | {"name", "interactions"} | set(
        ks_jax.case.CUMULATIVE_OUTPUTS) | set(CRUSH_FIELDS)
    # the crush-energy results (docs/model.md, "Crush energy") are there, null, for a vehicle without a crush profile
    assert all(res["vehicles"][0][k] is None for k in CRUSH_FIELDS)
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_every_command_writes_json_as_cases(tmp_path, capsys):
    """``solve --json`` and ``fit --json`` write one shape, ``{"cases": [...]}``, for a file of one case as
    for a file of several; each fit entry is its ``FitResult.to_dict``, and a case that was not fitted has the
    same keys (its status, nothing fitted: tables empty, numbers null, not converged)."""
    fit_case = Path(ks_jax.__file__).parent / "cases" / "fit_seed_001.json"
    quick = ("--starts", "1", "--max-starts", "1")
    code, out, _ = run_cli(capsys, "fit", str(fit_case), "--json", *quick)
    d = json.loads(out)
    assert list(d) == ["cases"] and len(d["cases"]) == 1
    assert {"name", "estimate", "std", "residuals", "converged", "status"} <= set(d["cases"][0])
    code, out, _ = run_cli(capsys, "solve", str(fit_case), "--json")
    assert list(json.loads(out)) == ["cases"] and len(json.loads(out)["cases"]) == 1
    bad = json.loads(fit_case.read_text())
    bad["name"], bad["contact"]["restitution"] = "bad one", 3
    two = tmp_path / "two.json"
    two.write_text(json.dumps({"cases": [json.loads(fit_case.read_text()), bad]}))
    code, out, err = run_cli(capsys, "fit", str(two), "--json", *quick)
    cases = json.loads(out)["cases"]
    assert code == 1 and len(cases) == 2 and cases[0]["estimate"] == d["cases"][0]["estimate"]
    assert set(cases[1]) == set(cases[0]) and cases[1]["name"] == "bad one" and "restitution" in cases[1]["status"]
    assert cases[1]["estimate"] == {} and cases[1]["chi2"] is None and cases[1]["converged"] is False
