"""Results files of a sweep (``ks_jax.sweeps.files``): .csv (pyarrow or the csv module), .npz and .parquet,
written chunk by chunk as the command line does or from a kept sweep, in SI or US units, an unfinished file
never left behind."""

from __future__ import annotations

import csv

import numpy as np
import pytest

import ks_jax
from ks_jax import units as U
from ks_jax.case import CaseError
from ks_jax.cli import main
from ks_jax.cli.sweep import parse_over
from ks_jax.sweeps import ResultWriter, sweep, write_results
from samples import SEED0, SEED1, assert_no_flag_on_invalid_rows, read_table


@pytest.fixture(scope="module")
def case():
    return ks_jax.load_case(SEED0)


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".csv", ".npz", ".parquet"])
def test_cli_streams_the_same_file_as_a_kept_sweep(tmp_path, capsys, suffix):
    """``ks-jax sweep`` writes chunk by chunk (7 points a chunk here, so 39 chunks over a grid of 273
    points with invalid rows); the file holds what ``write_results`` writes from the same sweep kept
    in memory, and its values equal the sweep's."""
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    outs = ["contact.impulse_magnitude", "contact.sliding", "vehicles[1].delta_v[0]"]
    over = ["vehicles[1].speed=2:30:21", "contact.restitution=0:1.2:13"]  # restitution > 1: invalid rows
    args = ["sweep", str(SEED0), *sum((["--over", o] for o in over), []), *sum((["--output", o] for o in outs), []),
            "--chunk-size", "7", "--out", str(tmp_path / f"cli{suffix}")]
    assert main(args) == 0
    capsys.readouterr()
    kept = sweep(ks_jax.load_case(SEED0), dict(parse_over(o) for o in over), outputs=outs)
    assert 0 < kept.status_counts["ok"] < 273
    write_results(kept, tmp_path / f"kept{suffix}")
    if suffix == ".npz":
        a, b = np.load(tmp_path / "cli.npz"), np.load(tmp_path / "kept.npz")
        assert sorted(a.files) == sorted(b.files)
        for k in a.files:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
        for p in outs + ["status"]:
            np.testing.assert_array_equal(a[p], kept[p], err_msg=p)
        return
    a, b = read_table(tmp_path / f"cli{suffix}"), read_table(tmp_path / f"kept{suffix}")
    assert list(a) == ["vehicles[1].speed", "contact.restitution", *outs, "status", "status_text"] == list(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(a["vehicles[1].delta_v[0]"], kept["vehicles[1].delta_v[0]"].ravel())
    # the grid's values as typed: 2, 3.4, ..., 30 and 0, 0.1, ..., 1.2 (parse_over)
    speeds, eps = ([float(f"{a + step * k:.12g}") for k in range(n)] for a, step, n in ((2, 1.4, 21), (0, 0.1, 13)))
    np.testing.assert_array_equal(a["vehicles[1].speed"], np.repeat(speeds, 13))
    np.testing.assert_array_equal(a["contact.restitution"], np.tile(eps, 21))
    assert list(a["status_text"]) == [ks_jax.status_text(int(c)) for c in a["status"]]
    assert {"ok", "separating", "invalid: contact.restitution must be in [-1, 1]"} == set(a["status_text"])
    assert_no_flag_on_invalid_rows(a, kept)


@pytest.mark.slow
def test_csv_is_the_same_file_with_or_without_pyarrow(tmp_path, monkeypatch):
    """A .csv is written by pyarrow where it is installed, else by ks-jax's own formatting: the two files are
    the same bytes, in a grid, in zipped samples with invalid rows, in float32, in US units, and in a grid
    whose values and results span the notations (plain from 1e-6 to below 1e10, exponents outside); they
    read back to the sweep's values, bit for bit, NaN of invalid rows included (float32 as float32)."""
    pytest.importorskip("pyarrow")
    import ks_jax.sweeps.files as sweeps_module

    outs = ["contact.impulse_magnitude", "contact.sliding", "vehicles[0].pdof", "contact.impulse_tangential"]
    case = ks_jax.load_case(SEED0)
    rng = np.random.default_rng(3)
    grid = sweep(case, {"contact.normal": np.linspace(0, 1.2, 9), "contact.friction": np.linspace(0.1, 0.6, 7)},
                 outputs=outs)
    zipped = sweep(case, {"vehicles[1].speed": rng.uniform(1, 40, 50), "contact.restitution": rng.uniform(0, 1.3, 50)},
                   outputs=outs, mode="zip")
    narrow = sweep(case, {"vehicles[1].speed": np.linspace(2, 30, 11)}, outputs=outs, output_dtype=np.float32)
    # masses from 1e-3 to 1e12 kg: impulses and inputs on both sides of 1e-6 and 1e10, and 180.0 exactly
    wide = sweep(case, {"vehicles[0].mass": np.concatenate([10.0 ** np.arange(-3, 13), [180.0, 2.5e-5]])},
                 outputs=outs)
    assert grid["contact.sliding"].any() and not grid["contact.sliding"].all()
    assert np.isnan(zipped["contact.impulse_magnitude"]).any()  # restitution > 1: invalid rows
    assert narrow["contact.impulse_magnitude"].dtype == np.float32
    for name, result, units in (("grid", grid, "si"), ("zip", zipped, "si"), ("float32", narrow, "si"),
                                ("us", grid, "us"), ("wide", wide, "si")):
        write_results(result, tmp_path / f"{name}_arrow.csv", units=units)
        with monkeypatch.context() as m:
            m.setattr(sweeps_module, "_arrow_csv", lambda: None)
            write_results(result, tmp_path / f"{name}_csv.csv", units=units)
        text = (tmp_path / f"{name}_arrow.csv").read_bytes()
        assert text == (tmp_path / f"{name}_csv.csv").read_bytes(), name
        assert b"\r" not in text and text.endswith(b"\n")
        if units != "si":
            continue
        a = read_table(tmp_path / f"{name}_arrow.csv")
        assert list(a) == [*result.inputs(), *outs, "status", "status_text"]
        assert text.split(b"\n", 1)[0] == ",".join(a).encode()  # the header unquoted
        if name == "zip":  # with invalid rows
            assert_no_flag_on_invalid_rows(a, result)
        for p in outs:  # as the sweep stored them (float32 read as float32; None, a missing flag: False)
            a[p] = a[p].astype(result[p].dtype)
            np.testing.assert_array_equal(a[p], np.ravel(result[p]), err_msg=f"{name}: {p}")
        for p, v in result.inputs().items():
            np.testing.assert_array_equal(a[p], np.ravel(v), err_msg=f"{name}: {p}")
    # the notation, against texts written out by hand for each rule
    column = (tmp_path / "wide_csv.csv").read_text().splitlines()
    masses = [line.split(",")[0] for line in column[1:]]
    assert masses == ["0.001", "0.01", "0.1", "1", "10", "100", "1000", "10000", "100000", "1000000", "10000000",
                      "100000000", "1000000000", "1e+10", "1e+11", "1e+12", "180", "0.000025"]


@pytest.mark.parametrize("value, text", [
    (180.0, "180"), (0.1, "0.1"), (-0.0, "-0"), (1e-5, "0.00001"), (1.5e-6, "0.0000015"), (1e-7, "1e-7"),
    (9.5e-7, "9.5e-7"), (123456789.5, "123456789.5"), (9999999999.0, "9999999999"), (1e10, "1e+10"),
    (1.25e16, "1.25e+16"), (5e-324, "5e-324"), (float("nan"), "nan"), (-float("inf"), "-inf")])
def test_csv_numbers_are_the_shortest_text_in_one_notation(value, text):
    """Each number is the shortest text that reads back as it, plain from 1e-6 to below 1e10 (no trailing
    ".0"), in exponent form outside (the exponent unpadded); float32 by its own shortest text."""
    from ks_jax.sweeps.files import number_texts

    assert number_texts(np.array([value])) == [text]
    if np.isfinite(value):
        assert float(text) == value
    assert number_texts(np.array([0.1, 1e-5, 3e9, 2.5e10], np.float32)) == ["0.1", "0.00001", "3000000000", "2.5e+10"]
    assert number_texts(np.array([3, -7], np.int32)) == ["3", "-7"]


@pytest.mark.slow
def test_files_in_us_units(tmp_path, capsys):
    """``--units us`` writes the same sweep in mph, deg, ft lbf, lbf s, deg/s (the unit in each
    column's name), against the SI file divided by the units' definitions (1 mph = 0.44704 m/s,
    1 lbf = 4.4482216152605 N, 1 ft = 0.3048 m); dimensionless columns, booleans and the
    status unchanged, in .csv and .npz, and in ``SweepResult.table``."""
    mph, lbf, ft = 0.44704, 4.4482216152605, 0.3048
    outs = {"contact.energy_loss": ("ft lbf", lbf * ft), "contact.impulse_magnitude": ("lbf s", lbf),
            "vehicles[0].delta_v_magnitude": ("mph", mph), "vehicles[0].pdof": ("deg", 1.0),
            "vehicles[1].yaw_rate_after": ("deg/s", np.pi / 180), "contact.sliding": (None, None)}
    args = [str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:3", "--over", "contact.normal=0:40:3",
            "--over", "contact.restitution=0.1,1.2", *sum((["--output", o] for o in outs), []), "--no-progress"]
    for units, suffix in (("si", ".csv"), ("us", ".csv"), ("si", ".npz"), ("us", ".npz")):
        assert main(["sweep", *args, "--units", units, "--out", str(tmp_path / f"{units}{suffix}")]) == 0
    capsys.readouterr()
    si, us = read_table(tmp_path / "si.csv"), read_table(tmp_path / "us.csv")
    si_npz, us_npz = np.load(tmp_path / "si.npz"), np.load(tmp_path / "us.npz")
    assert list(us)[:3] == ["vehicles[1].speed [mph]", "contact.normal [deg]", "contact.restitution"]
    np.testing.assert_array_equal(us["vehicles[1].speed [mph]"], np.repeat([10.0, 20.0, 30.0], 6))
    np.testing.assert_array_equal(us["contact.normal [deg]"], np.tile(np.repeat([0.0, 20.0, 40.0], 2), 3))
    np.testing.assert_array_equal(us_npz["axis:vehicles[1].speed [mph]"], [10.0, 20.0, 30.0])
    np.testing.assert_array_equal(us_npz["axis:contact.normal [deg]"], [0.0, 20.0, 40.0])
    for p, (unit, scale) in outs.items():
        name = p if unit is None else f"{p} [{unit}]"
        if unit is None:
            np.testing.assert_array_equal(us[name], si[p])
            np.testing.assert_array_equal(us_npz[name], si_npz[p])
            continue
        assert np.isnan(si[p]).sum() == 9 and np.isnan(us[name]).sum() == 9  # restitution 1.2: invalid rows
        np.testing.assert_allclose(us[name], si[p] / scale, rtol=1e-13, atol=1e-12, err_msg=p)
        np.testing.assert_allclose(us_npz[name], si_npz[p] / scale, rtol=1e-13, atol=1e-12, err_msg=p)
    for k in ("status", "status_text"):
        np.testing.assert_array_equal(us[k], si[k])
    # the same columns from a kept sweep, in memory (SweepResult.table)
    kept = sweep(ks_jax.load_case(SEED1), {"vehicles[1].speed": np.array([10, 20, 30]) * mph,
                                           "contact.normal": np.radians([0, 20, 40]),
                                           "contact.restitution": np.array([0.1, 1.2])}, outputs=list(outs))
    table_si, table_us = kept.table(), kept.table(units="us")
    assert set(table_us) == set(us) and set(table_si) == set(si)
    for table, file in ((table_us, us), (table_si, si)):
        for k in table:
            if k in ("contact.sliding", "status_text"):  # None on the invalid rows, in the file and in the table
                np.testing.assert_array_equal(table[k], file[k], err_msg=k)
            else:
                np.testing.assert_allclose(table[k], file[k], rtol=1e-13, atol=1e-12, err_msg=k)
    with pytest.raises(CaseError, match="units = 'imperial': the units of a results file must be 'si' or 'us'"):
        write_results(kept, tmp_path / "x.csv", units="imperial")
    assert not (tmp_path / "x.csv").exists()
    with pytest.raises(ValueError, match="units = 'metric': units must be 'si' or 'us'"):
        kept.table(units="metric")
    streamed = sweep(ks_jax.load_case(SEED1), {"contact.restitution": np.array([0.1, 0.2])}, keep=False)
    with pytest.raises(CaseError, match="this sweep kept no results"):
        streamed.table()


@pytest.mark.slow
def test_writer_errors_keep_other_files(tmp_path, capsys):
    """A sweep that fails leaves no file of its own and an earlier file as it was, even after some
    chunks were written; a writer refuses chunks out of order and an incomplete file."""
    out = tmp_path / "r.csv"
    out.write_text("earlier results\n")
    code = main(["sweep", str(SEED0), "--mode", "zip", "--over", "vehicles[1].speed=1,2,3",
                 "--over", "contact.restitution=0,0.1", "--out", str(out)])
    assert code == 2 and "same number of values" in capsys.readouterr().err
    assert out.read_text() == "earlier results\n"
    for suffix in (".csv", ".npz"):
        (tmp_path / f"w{suffix}").write_text("earlier results\n")  # kept until a new file is complete
        w = ResultWriter(tmp_path / f"w{suffix}", {"contact.friction": np.array([0.1, 0.2, 0.3])}, "grid", (3,))
        w.chunk(0, 1, {"contact.impulse_magnitude": np.array([1.0]), "status": np.array([0], np.int8)})
        with pytest.raises(CaseError, match="arrived after 1 of 3"):
            w.chunk(2, 3, {"contact.impulse_magnitude": np.array([1.0]), "status": np.array([0], np.int8)})
        with pytest.raises(CaseError, match="1 of 3 points written"):
            w.close()
        w.abort()
        assert (tmp_path / f"w{suffix}").read_text() == "earlier results\n"
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # nothing left behind
    # over the restitution with the default outputs: the program of test_files_in_us_units' streamed sweep
    empty = sweep(ks_jax.load_case(SEED0), {"contact.restitution": [0.1, 0.2]}, index_range=(1, 1))
    with pytest.raises(CaseError, match="no points to write"):
        write_results(empty, tmp_path / "empty.csv")
    assert not (tmp_path / "empty.csv").exists()


@pytest.mark.slow
def test_file_columns_follow_the_outputs_asked(tmp_path, capsys):
    """The command writes the outputs in the order of --output, as write_results does for the same
    sweep (the compiled program returns them sorted by name)."""
    outs = ["vehicles[1].pdof", "contact.energy_loss", "vehicles[0].delta_v[1]"]
    args = ["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:3", *sum((["--output", o] for o in outs), []),
            "--out", str(tmp_path / "cli.csv")]
    assert main(args) == 0
    capsys.readouterr()
    write_results(sweep(ks_jax.load_case(SEED1), {"vehicles[1].speed": np.linspace(10, 30, 3) * U.MPH}, outputs=outs),
                  tmp_path / "kept.csv")
    cli, kept = (list(csv.reader((tmp_path / n).read_text().splitlines()))[0] for n in ("cli.csv", "kept.csv"))
    assert cli == kept == ["vehicles[1].speed", *outs, "status", "status_text"]
