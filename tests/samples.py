"""What several test modules share: the shipped cases, a case written in US units and its SI twin written
by hand from the exact unit definitions, a CLI runner, a reader of results files, a batch of cases with bad
rows placed at chunk boundaries, a leaf-by-leaf comparison of batched results, and the compiler of the
programs a test compares against."""

import copy
import csv
from pathlib import Path

import jax
import numpy as np
import pytest

import ks_jax
from ks_jax.cli import main
from ks_jax.compilation import compiler_options

CASES = Path(ks_jax.__file__).parent / "cases"  # the example cases shipped in the package
SEED0 = CASES / "seed_000_saturn_pontiac.json"
SEED1 = CASES / "seed_001_lucid_kia.toml"

# results a sweep test reads back: a vector component, an angle, a flag, scalars of both vehicles
SWEEP_OUTPUTS = ["contact.impulse_magnitude", "contact.energy_loss", "contact.sliding", "vehicles[0].delta_v[0]",
                 "vehicles[1].pdof", "vehicles[0].speed_after", "contact.impulse[1]"]

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
    """``ks-jax ARGV`` in this process: (exit status, stdout, stderr)."""
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def mass_sweep(case):
    """The ``--over`` of ``ks-jax sweep`` that tests/command_matrix.py runs on every case: the first vehicle's mass
    at 0.9, 1 and 1.1 times the case's, typed in kg (which reads the same in both unit systems; the middle point
    is the case itself)."""
    mass = float(np.asarray(ks_jax.get_input(case.inputs, "vehicles[0].mass")))
    return f"vehicles[0].mass={0.9 * mass!r}kg,{mass!r}kg,{1.1 * mass!r}kg"


def read_table(path):
    """Columns of a .csv or .parquet sweep file as NumPy arrays (status_text as str)."""
    if path.suffix == ".parquet":
        table = pytest.importorskip("pyarrow.parquet").read_table(path)
        return {c: table[c].to_numpy(zero_copy_only=False) for c in table.column_names}
    with path.open(newline="") as f:
        names, *rows = list(csv.reader(f))

    def column(values):
        flags = {v.lower() for v in values}
        if flags <= {"true", "false", ""} and flags != {""}:  # the csv module writes True, pyarrow true
            read = np.array([{"true": True, "false": False}.get(v.lower()) for v in values], dtype=object)
            return read if "" in flags else read.astype(bool)  # an empty field (invalid row): None
        try:
            return np.array(values, dtype=float)
        except ValueError:
            return np.array(values, dtype=str)

    return {n: column([r[k] for r in rows]) for k, n in enumerate(names)}


def assert_no_flag_on_invalid_rows(table, result):
    """A flag (``contact.sliding``) of an invalid row is an empty field (.csv) or null (.parquet): its
    numbers are NaN, and "false" would read as a result; every other row holds the sweep's flag."""
    invalid = table["status"] >= 10
    assert invalid.any() and not invalid.all()
    flags = table["contact.sliding"]
    assert all(f is None for f in flags[invalid])
    assert [bool(f) for f in flags[~invalid]] == np.ravel(result["contact.sliding"])[~invalid].tolist()
    assert all(isinstance(f, (bool, np.bool_)) for f in flags[~invalid])


def with_bad_rows(cases):
    """``cases`` (at least 101 of them) with an invalid row ending the first 64-row chunk and a row with
    restitution > 1 where an end-aligned last chunk computes rows again."""
    bad = copy.deepcopy(cases[63])
    bad["vehicles"][0]["inertia"] = -np.abs(np.asarray(bad["vehicles"][0]["inertia"]))
    wild = copy.deepcopy(cases[100])
    wild["contact"]["restitution"] = 1.5
    return cases[:63] + [bad] + cases[64:100] + [wild] + cases[101:]


def assert_same_leaves(batched, reference):
    """Two result trees leaf by leaf: floats to rounding, codes and flags exactly."""
    for a, b in zip(jax.tree_util.tree_leaves(batched), jax.tree_util.tree_leaves(reference)):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape
        if a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
        else:
            np.testing.assert_array_equal(a, b)


def reference_jit(fun, **jit_kwargs):
    """``jax.jit`` compiled with the quick settings that ``ks_jax.solve`` uses on a CPU (the same IEEE
    arithmetic, half the compile time), for a program that is a test's independent route to a result (a
    per-row gradient, a plain sum, a central difference), and for the test's own wrapper of a gradient or
    Hessian through the library (``jax.jit(jax.grad(loss))``): what those tests check, the library's
    derivatives (its batching rule, ``sum_over_rows``' chunks), is traced the same whatever XLA's settings.
    The library's own programs (``exchange_batch``, ``sweep``, ``solve``, the fit) compile as users get them."""
    return jax.jit(fun, compiler_options=compiler_options(True), **jit_kwargs)


def assert_json_close(a, b, where="json"):
    """Two parsed JSON documents (or ``to_dict`` results) equal, their numbers to 1e-12 of themselves (1e-12
    absolute near 0): two compiled programs of one computation may round its last bits apart."""
    assert type(a) is type(b), where
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            assert_json_close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            assert_json_close(x, y, f"{where}[{k}]")
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-12), where
    else:
        assert a == b, where
