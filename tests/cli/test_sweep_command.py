"""``ks-jax sweep``: ``--over`` values (grids, lists, random draws, units), the file written, bad arguments
refused before anything is solved, a killed sweep leaving an earlier file as it was, undefined results named."""

from __future__ import annotations

import csv
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import ks_jax
from ks_jax import units as U
from ks_jax.case import CaseError
from ks_jax.cli import main
from ks_jax.cli.sweep import parse_over
from ks_jax.sweeps import sweep
from samples import SEED0, SEED1, SWEEP_OUTPUTS as OUTPUTS, read_table


@pytest.fixture(scope="module")
def case():
    return ks_jax.load_case(SEED0)


@pytest.mark.slow
def test_bad_sweep_arguments_are_refused_by_name(case):
    """What is not a sweep is refused with its field and rule, before anything is solved; a sweep too
    large to keep in memory names the memory and the way round it."""
    speed = {"vehicles[1].speed": [1.0, 2.0]}
    for kwargs, message in (
            (dict(over={3: [1.0]}), "sweep over 3: an input path is a string"),
            (dict(over=[("vehicles[1].speed", [5.0])]), r"give a mapping \{path: values\}, got list"),
            (dict(over={"contact.restitution": [True, False]}), "the values are booleans"),
            (dict(over=speed, index_range=(1,)), r"index_range = \(1,\): give two whole numbers"),
            (dict(over=speed, index_range=(0.7, 2.9)), r"index_range = \(0.7, 2.9\): lo and hi must be whole"),
            (dict(over=speed, chunk_size=2.7), "chunk_size = 2.7: must be a whole number"),
            (dict(over={f"vehicles[{i}].{f}": np.zeros(10**5) for i in (0, 1) for f in ("speed", "mass")}),
             "1e\\+20 points, more than a 64-bit index counts"),
            (dict(over={"vehicles[1].speed": np.zeros(10**6), "contact.friction": np.zeros(10**6)}),
             # 6 float64 outputs + the sliding flag + the status: 50 bytes a point, 5e13 bytes = 4.66e4 GiB
             r"keeping 1000000000000 points of 7 outputs needs 4.66e\+04 GiB, more than this machine's .*keep=False")):
        with pytest.raises(CaseError, match=message):
            sweep(case, outputs=OUTPUTS, **kwargs)
    with pytest.raises(CaseError, match="a value is missing between commas"):
        parse_over("vehicles[1].speed=1,,2")
    with pytest.raises(CaseError, match="a grid of N = 1000000000000 values needs .* GiB"):
        parse_over("vehicles[1].speed=0:1e9:1000000000000")
    part = sweep(case, {"vehicles[1].speed": np.linspace(1, 30, 10)}, mode="zip", outputs=OUTPUTS, index_range=(0, 5))
    with pytest.raises(CaseError, match="this result holds points 0..4 of a sweep"):
        part.thinned(limit=2)


def test_parse_over_units():
    path, v = parse_over("vehicles[1].speed=10mph:60mph:51")
    assert path == "vehicles[1].speed" and len(v) == 51
    np.testing.assert_allclose(v[[0, -1]], np.array([10, 60]) * ks_jax.units.MPH)
    _, yaw = parse_over("vehicles[0].yaw=0:90:3")  # bare angles are degrees
    np.testing.assert_allclose(yaw, np.radians([0, 45, 90]))
    _, rate = parse_over("vehicles[0].yaw_rate=10,20")  # bare rates are deg/s
    np.testing.assert_allclose(rate, np.radians([10, 20]))
    with pytest.raises(CaseError, match="START:STOP:N"):
        parse_over("vehicles[0].yaw")
    with pytest.raises(CaseError, match=r"vehicles\[1\].speed: START = 'nan' must be a finite number"):
        parse_over("vehicles[1].speed=nan:60mph:5")  # linspace would make every point but the last NaN
    with pytest.raises(CaseError, match="'-inf mph' is not a '<number> <unit>' quantity"):
        parse_over("vehicles[1].speed=10mph:-inf mph:5")


def test_parse_over_random_values():
    from ks_jax.cli.sweep import Draws, draw_over

    mph = 1609.344 / 3600
    draws = Draws("vehicles[1].speed", "normal", 20 * mph, 2 * mph)
    assert parse_over("vehicles[1].speed=normal:20mph:2mph") == ("vehicles[1].speed", draws)
    _, d = parse_over("vehicles[0].yaw=uniform:-5:5")  # bare angles are degrees, as everywhere
    assert (d.law, d.a, d.b) == ("uniform", np.radians(-5), np.radians(5))
    for spec, words in (("normal:0.1:-0.02", "SD must be >= 0"), ("uniform:0.3:0.1", "LO must not exceed HI"),
                        ("uniform:0:nan", "HI = 'nan' must be a finite number"),
                        ("normal:1", "expected normal:MEAN:SD")):
        with pytest.raises(CaseError, match=words):
            parse_over(f"contact.restitution={spec}")
    specs = [parse_over("contact.restitution=uniform:0:0.3"), parse_over("contact.friction=0.4,0.5,0.6")]
    with pytest.raises(CaseError, match="need --samples N"):
        draw_over(specs, None, None, 0)
    with pytest.raises(CaseError, match="not a grid"):
        draw_over(specs, "grid", 3, 0)
    with pytest.raises(CaseError, match="--samples N is for random values"):
        draw_over(specs[1:], None, 3, 0)
    over, mode = draw_over(specs, None, 3, 11)
    assert mode == "zip" and list(over) == ["contact.restitution", "contact.friction"]
    np.testing.assert_array_equal(over["contact.restitution"], np.random.default_rng(11).uniform(0, 0.3, 3))
    np.testing.assert_array_equal(over["contact.friction"], [0.4, 0.5, 0.6])


@pytest.mark.slow
def test_cli_monte_carlo_sweep(tmp_path, capsys, case):
    """Random inputs from the command line: the draws are numpy's default_rng(seed) in the order of the
    --over options, they are stored as the axes of the file, and the results are the sweep of those
    samples; the normal draws' mean is 20 mph within five standard errors."""
    out = tmp_path / "mc.npz"
    argv = ["sweep", str(SEED0), "--over", "vehicles[1].speed=normal:20mph:2mph", "--over",
            "contact.restitution=uniform:0.05:0.15", "--samples", "2000", "--seed", "7",
            "--output", "vehicles[0].delta_v_magnitude", "--out", str(out)]
    assert main(argv) == 0
    assert "2000 points (zip" in capsys.readouterr().out
    mph = 1609.344 / 3600
    rng = np.random.default_rng(7)
    speed, eps = rng.normal(20 * mph, 2 * mph, 2000), rng.uniform(0.05, 0.15, 2000)
    data = np.load(out)
    np.testing.assert_array_equal(data["axis:vehicles[1].speed"], speed)
    np.testing.assert_array_equal(data["axis:contact.restitution"], eps)
    assert abs(speed.mean() / mph - 20) < 5 * 2 / np.sqrt(2000)
    kept = sweep(case, {"vehicles[1].speed": speed, "contact.restitution": eps}, mode="zip",
                 outputs=["vehicles[0].delta_v_magnitude"])
    np.testing.assert_array_equal(data["vehicles[0].delta_v_magnitude"], kept["vehicles[0].delta_v_magnitude"])


@pytest.mark.slow
def test_cli_writes_csv_and_npz(tmp_path, capsys):
    csv_path, npz_path = tmp_path / "r.csv", tmp_path / "r.npz"
    args = [str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:5", "--over", "contact.restitution=0:1.5:4",
            "--output", "contact.impulse_magnitude", "--output", "vehicles[0].delta_v_magnitude"]
    assert main(["sweep", *args, "--out", str(csv_path)]) == 0
    out = capsys.readouterr().out
    assert "20 points" in out and "ok: 15" in out and "invalid: contact.restitution" in out
    lines = list(csv.reader(csv_path.read_text().splitlines()))
    assert lines[0] == ["vehicles[1].speed", "contact.restitution", "contact.impulse_magnitude",
                                   "vehicles[0].delta_v_magnitude", "status", "status_text"]
    assert len(lines) == 21
    assert main(["sweep", *args, "--out", str(npz_path)]) == 0
    data = np.load(npz_path)
    assert data["contact.impulse_magnitude"].shape == (5, 4)
    row = lines[1 + 4 * 2 + 1]  # speed index 2, restitution index 1
    np.testing.assert_allclose(float(row[2]), data["contact.impulse_magnitude"][2, 1], rtol=1e-15)
    np.testing.assert_allclose(data["axis:vehicles[1].speed"], np.linspace(10, 30, 5) * ks_jax.units.MPH)


@pytest.mark.slow
def test_large_csv_without_pyarrow_suggests_it(tmp_path, capsys, monkeypatch):
    """Without pyarrow a large .csv is written by the csv module, and the command says how to write it
    faster; the file holds every point either way."""
    pytest.importorskip("pyarrow")
    import ks_jax.cli.sweep as command
    import ks_jax.sweeps.files as sweeps_module

    hint = "written several times faster with pyarrow installed"
    monkeypatch.setattr(command, "CSV_HINT_POINTS", 40)
    args = ["sweep", str(SEED0), "--over", "vehicles[1].speed=2:30:8", "--over", "contact.friction=0:1:5",
            "--output", "contact.impulse_magnitude", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "a.csv")]) == 0
    assert hint not in capsys.readouterr().out  # pyarrow wrote it
    monkeypatch.setattr(sweeps_module, "_arrow_csv", lambda: None)
    assert main([*args, "--out", str(tmp_path / "b.csv")]) == 0
    assert hint in capsys.readouterr().out
    monkeypatch.setattr(command, "CSV_HINT_POINTS", 41)
    assert main([*args, "--out", str(tmp_path / "c.csv")]) == 0
    assert hint not in capsys.readouterr().out  # fewer points than the threshold
    assert len(read_table(tmp_path / "b.csv")["status"]) == 40
    np.testing.assert_array_equal(read_table(tmp_path / "a.csv")["contact.impulse_magnitude"],
                                  read_table(tmp_path / "b.csv")["contact.impulse_magnitude"])


@pytest.mark.slow
def test_swept_values_in_us_units_read_as_typed(tmp_path, capsys):
    """A value typed in mph or ft comes back from SI as 24.999999999999996 mph or 1.9999999999999996 ft;
    the file (and the .npz axis) give it as typed, and leave values that are not short decimals as
    converted (within 2 units in the last place)."""
    args = ["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:5",
            "--over", "vehicles[0].cg_height=1ft:3ft:7", "--output", "contact.impulse_magnitude", "--units", "us",
            "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "us.csv")]) == 0
    assert main([*args, "--out", str(tmp_path / "us.npz")]) == 0
    capsys.readouterr()
    # a grid's own values: linspace's rounding undone, to 2 ulp (0.05, not 0.049999999999999996)
    assert np.linspace(0, 0.3, 7)[1] != 0.05
    np.testing.assert_array_equal(parse_over("contact.restitution=0:0.3:7")[1], [0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3])
    np.testing.assert_allclose(parse_over("vehicles[1].speed=3:60:7")[1], np.linspace(3, 60, 7), rtol=5e-16, atol=0)
    # converted from a unit (deg/s here): solved as converted, and the US file types it back
    np.testing.assert_array_equal(parse_over("vehicles[0].yaw_rate=-30:30:3")[1], np.radians([-30.0, 0.0, 30.0]))
    miles, feet = np.linspace(10 * U.MPH, 30 * U.MPH, 5) / U.MPH, np.linspace(1 * U.FT, 3 * U.FT, 7) / U.FT
    assert miles[3] != 25.0 and feet[3] != 2.0  # what plain conversion gives
    table, npz = read_table(tmp_path / "us.csv"), np.load(tmp_path / "us.npz")
    for speeds, heights in ((table["vehicles[1].speed [mph]"][::7], table["vehicles[0].cg_height [ft]"][:7]),
                            (npz["axis:vehicles[1].speed [mph]"], npz["axis:vehicles[0].cg_height [ft]"])):
        np.testing.assert_array_equal(speeds, [10.0, 15.0, 20.0, 25.0, 30.0])
        np.testing.assert_array_equal(heights[::3], [1.0, 2.0, 3.0])
        np.testing.assert_allclose(heights, feet, rtol=4e-16)
        assert heights[1] != round(heights[1], 14)  # 4/3 ft: as converted


def test_cli_bad_path_is_a_clear_error(tmp_path, capsys):
    code = main(["sweep", str(SEED1), "--over", "vehicles[1].sped=1:2:3", "--out", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert code == 2 and "'sped' is not a vehicle input" in err and "Traceback" not in err
    code = main(["sweep", str(SEED1), "--over", "vehicles[1].speed=1:2:3", "--out", str(tmp_path / "x.xlsx")])
    assert code == 2 and "unknown file type" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("sig, code", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_killed_sweep_leaves_the_earlier_file(tmp_path, sig, code):
    """``ks-jax sweep`` stopped by a kill (a batch system's SIGTERM) or Ctrl-C while it writes: the points
    it finished are kept in out.incomplete.csv (whole rows, as many as it says), the earlier --out is as it
    was, the exit status says so (128 + signal, 130 for Ctrl-C) and no traceback is printed."""
    import signal
    import time

    out = tmp_path / "out.csv"
    out.write_text("earlier results\n")
    # the run's shared compile cache (tests/conftest.py): the second signal's sweep loads the first's program
    env = dict(os.environ, JAX_PLATFORMS="cpu", JAX_COMPILATION_CACHE_DIR=os.environ["KS_JAX_TEST_COMPILE_CACHE"],
               JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    proc = subprocess.Popen([sys.executable, "-m", "ks_jax.cli", "sweep", str(SEED1), "--over",
                             "vehicles[1].speed=1:40:3000", "--over", "contact.restitution=0:0.5:1000",
                             "--out", str(out), "--no-progress"], stderr=subprocess.PIPE, text=True, env=env)
    partial = tmp_path / ".out.csv.partial"
    deadline = time.monotonic() + 120
    # a chunk written (16384 rows of about 200 bytes), not only the file opened: a kill between the opening and
    # the first row leaves no point to keep
    def written():
        try:
            return partial.stat().st_size
        except FileNotFoundError:
            return 0

    while written() <= 1 << 20 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert partial.exists(), "the sweep never started writing"
    proc.send_signal(getattr(signal, sig))
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == code, err[-2000:]
    assert "Traceback" not in err
    assert out.read_text() == "earlier results\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv", "out.incomplete.csv"]
    said = re.search(r"stopped: ([\d,]+) of 3,000,000 points written to (\S+); \S+ is left as it was", err)
    assert said and said.group(2) == str(tmp_path / "out.incomplete.csv"), err[-2000:]
    rows = read_table(tmp_path / "out.incomplete.csv")
    n = int(said.group(1).replace(",", ""))
    assert 0 < n < 3_000_000 and len(rows["status"]) == n
    # the first points of the grid, in order (row-major: restitution varies fastest), each row whole
    np.testing.assert_allclose(rows["contact.restitution"][:1000], np.linspace(0, 0.5, 1000))
    assert np.all(np.isfinite(rows["contact.impulse_magnitude"]))


def test_a_signal_that_a_library_swallowed_still_stops_the_command(monkeypatch):
    """Ctrl-C raises KeyboardInterrupt wherever the command's main thread is, possibly inside a library that
    catches it (``test_a_killed_sweep_leaves_the_earlier_file`` once saw a sweep finish with exit status 0
    after its SIGINT). The command keeps the signal, and ``raise_if_stopped``, called before each chunk is
    written and before the file is finished, raises it again: KeyboardInterrupt for SIGINT, exit status
    128 + 15 for SIGTERM."""
    import signal

    from ks_jax.cli import signals

    monkeypatch.setattr(signals, "_SIGNALLED", [])
    signals.raise_if_stopped()  # no signal: nothing
    for sig, raised in ((signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, SystemExit)):
        try:
            signals.stopped(sig, None)  # as the handler runs, inside a library that swallows what it raises
        except (KeyboardInterrupt, SystemExit):
            pass
        with pytest.raises(raised) as info:
            signals.raise_if_stopped()
        assert raised is KeyboardInterrupt or info.value.code == 128 + 15


def test_one_input_named_twice_is_refused(tmp_path, capsys):
    """yaw_rate is angular_velocity[2], inertia[0][1] is inertia[1][0], a space changes nothing, and a
    path given twice is one input: the later would override the earlier under the earlier's name."""
    case = ks_jax.load_case(SEED1)
    for over, words in (({"vehicles[0].yaw_rate": [0, 1], "vehicles[0].angular_velocity[2]": [0, 1]},
                         "'vehicles[0].angular_velocity[2]' and 'vehicles[0].yaw_rate'"),
                        ({"vehicles[1].speed": [1.0], "vehicles[1]. speed": [2.0]},
                         "'vehicles[1]. speed' and 'vehicles[1].speed'"),
                        ({"vehicles[0].inertia[0][1]": [0.0], "vehicles[0].inertia[1][0]": [1.0]},
                         "'vehicles[0].inertia[1][0]' and 'vehicles[0].inertia[0][1]'")):
        with pytest.raises(CaseError, match=re.escape(words + ": both name the same input")):
            sweep(case, over)
    code = main(["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:3", "--over", "vehicles[1].speed=1,2",
                 "--out", str(tmp_path / "x.csv")])
    assert code == 2 and "--over 'vehicles[1].speed' twice: both name the same input" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.slow
def test_undefined_results_are_nan_and_named(case, tmp_path, capsys):
    """Where a solved point has no impulse (restitution -1: (1 + eps) J_c = 0 by hand), its PDOF and impulse
    direction are undefined: NaN in the sweep, not the stand-in 0 (a frontal impact), as null in the JSON of
    ``ks-jax solve``; with the centroid 10 ft up, above both boxes, both crushes are 0 and EES is undefined
    (docs/model.md, "Results"). The summary counts them and says why."""
    over = {"contact.restitution": np.array([-1.0, 0.1]), "contact.point[2]": np.array([0.54, 10 * U.FT])}
    outs = ["vehicles[0].pdof", "vehicles[1].pdof_clock", "contact.impulse_azimuth", "vehicles[0].ees",
            "contact.impulse_magnitude"]
    r = sweep(case, over, outputs=outs)
    assert r.status_counts == {"ok": 4}
    assert np.all(r["contact.impulse_magnitude"][0] == 0) and np.all(r["contact.impulse_magnitude"][1] > 0)
    for p in outs[:3]:
        assert np.isnan(r[p][0]).all() and np.isfinite(r[p][1]).all(), p
    np.testing.assert_allclose(r["vehicles[0].pdof"][1], 180.0, atol=5.0)  # struck from behind
    assert np.isnan(r["vehicles[0].ees"][:, 1]).all() and np.isfinite(r["vehicles[0].ees"][:, 0]).all()
    assert r.undefined == {"vehicles[0].pdof": 2, "vehicles[1].pdof_clock": 2, "contact.impulse_azimuth": 2,
                           "vehicles[0].ees": 2}
    text = r.summary()
    assert "undefined (NaN) at 2 solved points: vehicles[0].pdof, where no impulse was exchanged" in text
    assert "undefined (NaN) at 2 solved points: vehicles[0].ees, where both crushes are 0" in text
    # the command over the same grid and outputs (one program with the sweep above)
    code = main(["sweep", str(SEED0), "--over", "contact.restitution=-1,0.1", "--over", "contact.point[2]=0.54m,10ft",
                 *sum((["--output", p] for p in outs), []), "--out", str(tmp_path / "u.csv")])
    out = capsys.readouterr().out
    assert code == 0 and "undefined (NaN) at 2 solved points: vehicles[0].pdof, where no impulse" in out
    assert "undefined (NaN) at 2 solved points: vehicles[0].ees, where both crushes are 0" in out


def test_cli_over_refuses_a_dropped_stop_and_non_finite_values():
    with pytest.raises(CaseError, match="N = 1 would solve START alone and leave STOP out"):
        parse_over("vehicles[1].speed=60mph:10mph:1")
    assert parse_over("vehicles[1].speed=10mph:10mph:1")[1].tolist() == [10 * U.MPH]
    for spec in ("contact.restitution=0.1,nan", "contact.restitution=inf,0.2"):
        with pytest.raises(CaseError, match="must be a finite number"):
            parse_over(spec)


def test_bare_numbers_with_units_us_are_refused_where_the_units_differ(tmp_path, capsys):
    """``--units us`` sets the file's units, not the typed values': a bare speed, length, mass or inertia is
    refused with both ways to write it, before any file exists; values with units, 0, and the kinds whose
    bare unit is the same in both systems (restitution, friction, times in s, angles in deg, rates in
    deg/s) are read as in SI, against the exact unit definitions."""
    mph, ft, lb = 0.44704, 0.3048, 0.45359237
    for spec, fix in (("vehicles[1].speed=20:40:5", "write 20mph:40mph:5, or give SI values with units "
                                                     "(20m/s:40m/s:5)"),
                      ("vehicles[0].cg_height=0.5,0.6", "write 0.5ft,0.6ft, or give SI values with units (0.5m,0.6m)"),
                      ("vehicles[0].mass=normal:1500:30", "write normal:1500lb:30lb"),
                      ("vehicles[1].speed=0:40:3", "write 0mph:40mph:3")):
        with pytest.raises(CaseError, match="bare numbers are SI .* but --units us was given") as err:
            parse_over(spec, "us")
        assert fix in str(err.value)
        assert parse_over(spec, "si")[0] == spec.split("=")[0]  # in SI the same text is read
    out = tmp_path / "us.csv"
    code = main(["sweep", str(SEED1), "--over", "vehicles[1].speed=20:40:5", "--units", "us", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "ks-jax: error: --over vehicles[1].speed=20:40:5: bare numbers are SI (m/s)" in err
    assert "write 20mph:40mph:5" in err and not out.exists()
    np.testing.assert_allclose(parse_over("vehicles[1].speed=20mph:40mph:5", "us")[1], np.linspace(20, 40, 5) * mph,
                               rtol=1e-15)
    np.testing.assert_allclose(parse_over("vehicles[1].speed=0:40mph:3", "us")[1], [0, 20 * mph, 40 * mph], rtol=1e-15)
    np.testing.assert_allclose(parse_over("vehicles[0].mass=3000lb,1400kg", "us")[1], [3000 * lb, 1400], rtol=1e-15)
    np.testing.assert_allclose(parse_over("vehicles[0].cg_height=1ft:2ft:2", "us")[1], [ft, 2 * ft], rtol=1e-15)
    for spec, values in (("contact.restitution=0:0.3:4", [0, 0.1, 0.2, 0.3]), ("contact.friction=0.4,0.6", [0.4, 0.6]),
                         ("contact.penetration_time=0.02,0.05", [0.02, 0.05]),
                         ("vehicles[0].yaw=0:90:3", np.radians([0, 45, 90])),
                         ("vehicles[0].yaw_rate=uniform:10:20", None)):
        path, got = parse_over(spec, "us")
        if values is None:
            assert (got.a, got.b) == (np.radians(10), np.radians(20))
        else:
            np.testing.assert_allclose(got, values, rtol=1e-15, atol=1e-17)
