"""Every command, run as users run it, on every case the project ships: the matrix's sources and its checks. The
tests are ``test_matrix_*.py``, one file per group of sources (``GROUPS``), so that test workers that each take a
whole file (``--dist loadfile``) share the matrix; ``test_matrix.py`` checks that the groups hold every source once.

The cases are found, not listed: every file in ``ks_jax/cases/``, ``docs/examples/`` and ``docs/validation/`` (its
folders too; ``NOT_CASES`` names the one data file there that is not a case file), and every whole case written out
in a JSON or TOML block of ``docs/*.md``, joins the matrix by being there. Each file is solved (the panel, ``--json``,
``--plot``, ``--units us`` and ``--units si``); each case with ``unknowns`` is fitted (the report, ``--json``,
``--plot``, ``--monte-carlo``, ``--posterior``); each case is swept over one of its inputs into every results format
and a picture. Every run must end with exit status 0 and no traceback, and every ``--json`` must parse, have the one
shape every command writes (``{"cases": [...]}``) and carry, for each case, the keys that docs/model.md names for it.

The commands run in this process (``ks_jax.cli.main``), so that the runs share their compiled programs.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

import ks_jax
from ks_jax.case import CaseError, cases_from_data, load_cases
from ks_jax.compilation import free_programs
from samples import mass_sweep, run_cli

ROOT = Path(__file__).resolve().parents[1]
PACKAGED = Path(ks_jax.__file__).parent / "cases"
# shipped beside the cases, read by the measured tests' script: the figures recorded for them, not cases
NOT_CASES = {ROOT / "docs" / "validation" / "measured" / "recorded.json"}
FILES = sorted(p for folder in (PACKAGED, ROOT / "docs" / "examples", ROOT / "docs" / "validation")
               for p in (folder.rglob("*") if folder.name == "validation" else folder.iterdir())
               if p.suffix in (".json", ".toml") and p not in NOT_CASES)


def doc_blocks():
    """{name: (suffix, text)} of the JSON and TOML blocks of docs/*.md that hold whole cases: a "vehicles" or
    "cases" field, and every field a case needs (a block that shows a few fields of a case is a fragment)."""
    found = {}
    for doc in sorted((ROOT / "docs").glob("*.md")):
        blocks = re.findall(r"```(json|toml)\n(.*?)```", doc.read_text(encoding="utf-8"), re.S)
        for k, (kind, body) in enumerate(blocks):
            try:
                data = json.loads(body) if kind == "json" else tomllib.loads(body)
            except ValueError:
                continue
            if not (isinstance(data, dict) and ("vehicles" in data or "cases" in data)):
                continue
            try:
                cases_from_data(data)
            except CaseError:
                continue
            found[f"{doc.relative_to(ROOT)}#{k}"] = (f".{kind}", body)
    return found


BLOCKS = doc_blocks()
SOURCES = [str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else f"ks_jax/cases/{p.name}" for p in FILES]
SOURCES += list(BLOCKS)


def case_file(source, folder):
    """The file of ``source``: a shipped file where it is, a doc's block written into ``folder``."""
    if source not in BLOCKS:
        return next(p for p, s in zip(FILES, SOURCES) if s == source)
    suffix, body = BLOCKS[source]
    path = folder / f"case{suffix}"
    path.write_text(body, encoding="utf-8")
    return path


def _cases(source):
    """The cases of ``source``, read once at collection."""
    if source not in BLOCKS:
        return load_cases(case_file(source, None))
    suffix, body = BLOCKS[source]
    data = json.loads(body) if suffix == ".json" else tomllib.loads(body)
    return cases_from_data(data, source)


FITTED = [s for s in SOURCES if any("unknowns" in c.raw for c in _cases(s))]


def _table_names(text, heading):
    """The names in the first column of the table under the line ``heading`` of docs/model.md."""
    rows = text.split(heading, 1)[1].split("\n\n", 2)[1]
    return {n for row in rows.splitlines()[2:] for n in re.findall(r"`([a-z_]+)`", row.split("|")[1])}


def documented_keys():
    """What docs/model.md says each ``--json`` object carries: the results of its "Results" tables (per
    exchange, per vehicle, the motion to rest's) and the keys its "JSON output" section lists for a solved and
    a fitted case (those always there: the ones before "; and")."""
    text = (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    rest = text.split("A case with a `road` adds each vehicle's motion to rest:", 1)[1].split("(", 1)[0]
    fit_keys = text.split("- A case of `ks-jax fit`:", 1)[1].split("; and", 1)[0]
    return {"contact": _table_names(text, "Per exchange (`contact.*`):"),
            "vehicle": _table_names(text, "Per vehicle (`vehicles[i].*`, i = 0 for vehicle 1):") | {"name"},
            "rest": set(re.findall(r"`([a-z_]+)`", rest)),
            "solved case": {"name", "contact", "vehicles"},
            "fitted case": set(re.findall(r"`([a-z_0-9]+)`", fit_keys))}


KEYS = documented_keys()


def assert_clean(code, out, err, what):
    """Exit status 0, no traceback, something printed."""
    assert "Traceback" not in out + err, f"{what}: a traceback:\n{err[-3000:]}"
    assert code == 0, f"{what}: exit status {code}\n{err[-3000:]}"
    assert out.strip(), f"{what}: printed nothing"


def parse_cases(out, what, count):
    """The one JSON shape of every command: {"cases": [one object per case of the file]}, strictly JSON."""
    data = json.loads(out, parse_constant=lambda c: pytest.fail(f"{what}: {c} in the JSON"))
    assert isinstance(data, dict) and set(data) == {"cases"}, f"{what}: top level {type(data).__name__}"
    assert isinstance(data["cases"], list) and len(data["cases"]) == count, what
    return data["cases"]


def assert_documented(obj, kind, what):
    """The keys docs/model.md names for ``kind`` are there."""
    missing = KEYS[kind] - set(obj)
    assert not missing, f"{what}: keys that docs/model.md names are missing: {sorted(missing)}"


def check_solve(path, cases, capsys, tmp_path):
    """solve: the panel, in either unit system alone, --json and --plot. Returns the JSON's cases."""
    what = f"ks-jax solve {path.name}"
    assert_clean(*run_cli(capsys, "solve", str(path)), what)
    for units in ("us", "si"):
        assert_clean(*run_cli(capsys, "solve", str(path), "--units", units), f"{what} --units {units}")
    code, out, err = run_cli(capsys, "solve", str(path), "--json")
    assert_clean(code, out, err, f"{what} --json")
    for case, obj in zip(cases, parse_cases(out, f"{what} --json", len(cases))):
        assert obj["name"] == case.name
        assert_documented(obj, "solved case", f"{what} --json, case '{case.name}'")
        assert_documented(obj["contact"], "contact", f"{what} --json, case '{case.name}' contact")
        for v in obj["vehicles"]:
            assert_documented(v, "vehicle", f"{what} --json, case '{case.name}' vehicle")
            if case.motion is not None:
                assert_documented(v, "rest", f"{what} --json, case '{case.name}' vehicle")
    png = tmp_path / "top.png"
    assert_clean(*run_cli(capsys, "solve", str(path), "--plot", str(png)), f"{what} --plot")
    assert png.stat().st_size > 0
    return parse_cases(out, f"{what} --json", len(cases))


def check_fit(path, cases, capsys, tmp_path):
    """fit: the report, --json, --plot, --monte-carlo 20 and --posterior with a few draws, in two runs as users
    combine them: the report with the Monte Carlo refits and the top view; the JSON with the posterior and its
    corner plot."""
    what = f"ks-jax fit {path.name}"
    png = tmp_path / "fit.png"
    code, out, err = run_cli(capsys, "fit", str(path), "--monte-carlo", "20", "--plot", str(png))
    assert_clean(code, out, err, f"{what} --monte-carlo 20 --plot")
    assert "monte carlo" in out.lower(), f"{what} --monte-carlo 20: the report does not show the refits"
    assert png.stat().st_size > 0
    png = tmp_path / "post.png"
    code, out, err = run_cli(capsys, "fit", str(path), "--posterior", "6", "--chains", "2", "--json",
                             "--plot", str(png))
    assert_clean(code, out, err, f"{what} --posterior 6 --chains 2 --json --plot")
    fitted = parse_cases(out, f"{what} --json", len(cases))
    for case, obj in zip(cases, fitted):
        assert obj["name"] == case.name
        assert_documented(obj, "fitted case", f"{what} --json, case '{case.name}'")
        assert set(obj["posterior"]["unknowns"]) == set(obj["estimate"]), f"{what} --posterior: a summary per unknown"
    sampled = sum(obj.get("posterior") is not None for obj in fitted)
    corners = ["post_posterior.png"] if sampled == 1 else [f"post_posterior_{k}.png" for k in range(1, sampled + 1)]
    assert png.stat().st_size > 0 and all((tmp_path / name).stat().st_size > 0 for name in corners)


def solved_value(obj, path):
    """The value of result ``path`` ("contact.energy_loss", "vehicles[1].pdof") in a case of ``solve --json``
    (NaN for null; None where the JSON has no such vehicle: a fixed object's)."""
    where, leaf = path.split(".")
    name, index = re.fullmatch(r"(\w+)(?:\[(\d+)\])?", leaf).groups()
    if where == "contact":
        value = obj["contact"][name]
    else:
        i = int(where[len("vehicles["):-1])
        if i >= len(obj["vehicles"]):
            return None
        value = obj["vehicles"][i][name]
    if index is not None:
        value = value[int(index)]
    return float("nan") if value is None else float(value)


def check_sweep(path, k, case, solved, capsys, tmp_path):
    """sweep of case ``k`` over its first vehicle's mass into each results format, with a picture; the point at
    the case's own mass is ``solved`` (the case's object of ``solve --json``)."""
    what = f"ks-jax sweep {path.name} --case {k}"
    common = ["sweep", str(path), "--case", str(k), "--over", mass_sweep(case), "--no-progress"]
    for suffix, units in ((".csv", "us"), (".npz", "si"), (".parquet", "si")):
        out_file = tmp_path / f"grid{suffix}"
        extra = ["--plot", str(tmp_path / "grid.png")] if suffix == ".csv" else []
        assert_clean(*run_cli(capsys, *common, "--out", str(out_file), "--units", units, *extra),
                     f"{what} --out grid{suffix} --units {units}")
        assert out_file.stat().st_size > 0
    assert (tmp_path / "grid.png").stat().st_size > 0
    # the sweep's middle point is the case as it is: what `solve --json` gives for it
    table = np.load(tmp_path / "grid.npz")
    results = [c for c in table.files if c.startswith(("contact.", "vehicles["))]
    assert results, f"{what}: no results in the .npz"
    for column in results:
        expected = solved_value(solved, column)
        if expected is None:
            continue
        got = float(table[column][1])
        assert (math.isnan(got) and math.isnan(expected)) or abs(got - expected) <= 1e-9 * (1 + abs(expected)), \
            f"{what}: {column} at the case's own values is {got!r}, solve --json gives {expected!r}"


# The groups of sources, one test file each (``test_matrix_<group>.py``), by where a source is: a new source joins
# the group of its folder.
GROUPS = {
    "reconstructions": lambda s: s.startswith("ks_jax/cases/fit_"),
    "packaged": lambda s: s.startswith("ks_jax/cases/") and not s.startswith("ks_jax/cases/fit_"),
    "examples": lambda s: s.startswith("docs/examples/") or s in BLOCKS,
    "validation": lambda s: s.startswith("docs/validation/"),
}


def sources(group):
    """The sources of ``group`` (``GROUPS``), in the matrix's order."""
    return [s for s in SOURCES if GROUPS[group](s)]


def every_command(source, capsys, tmp_path):
    """Every command on ``source``'s cases, one after the other, so that they share the case's programs. They run
    with no other programs held, and free theirs once they have run: the sources are cases of every kind (motion to
    rest, fixed objects, automatic contact, fits and their samplers), and one source's commands on top of the
    programs of a worker's earlier files, or of the other sources, would hold more memory than any other test
    needs."""
    free_programs()
    try:
        path = case_file(source, tmp_path)
        cases = load_cases(path)
        solved = check_solve(path, cases, capsys, tmp_path)
        if source in FITTED:
            check_fit(path, cases, capsys, tmp_path)
        for k, case in enumerate(cases):
            if case.valid:
                check_sweep(path, k, case, solved[k], capsys, tmp_path)
    finally:
        free_programs()


def matrix_test(group):
    """The test of a group's file: ``every_command`` on each of its sources, a test each."""

    @pytest.mark.slow
    @pytest.mark.parametrize("source", sources(group))
    def test_every_command(source, capsys, tmp_path):
        every_command(source, capsys, tmp_path)

    return test_every_command
