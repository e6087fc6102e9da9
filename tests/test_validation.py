"""docs/validation.md: every published or closed-form case is reproduced within its stated tolerance, and
the page is exactly what docs/validation.py prints, so that it cannot drift from the code. The measured crash
tests (its section 5): the forward cases hold one rule, ks-jax's values are the recorded figures, and the command
line gives the same values as the page."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from samples import run_cli

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.fixture(scope="module")
def validation():
    spec = importlib.util.spec_from_file_location("ks_jax_docs_validation", DOCS / "validation.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        sys.modules.pop(spec.name, None)
    return module


@pytest.fixture(scope="module")
def groups(validation):
    return validation.tables()


@pytest.fixture(scope="module")
def measured(validation):
    return validation.measured


@pytest.fixture(scope="module")
def measured_groups(measured):
    return measured.tables()


@pytest.mark.slow
def test_every_difference_is_within_its_tolerance(validation, groups):
    compared = 0
    for group, rows in groups.items():
        for row in rows:
            assert row.within, (group, row)
            compared += 1
    assert compared >= 60, compared
    assert {g: len(r) for g, r in groups.items() if g != "wall"} == {"manual": 12, "inline": 12, "brach": 28}


@pytest.mark.slow
def test_every_group_has_its_cases(groups):
    starts = {g: sum(1 for r in rows if r.case) for g, rows in groups.items()}
    assert starts == {"manual": 2, "inline": 3, "brach": 4, "wall": 3}


@pytest.mark.slow
def test_the_page_is_what_the_script_prints(validation, groups, measured_groups):
    assert (DOCS / "validation.md").read_text() == validation.markdown(groups, measured_groups), (
        "docs/validation.md is stale: run python docs/validation.py --write")


def test_the_measured_tests_are_there_and_their_forward_cases_hold_one_rule(measured):
    """At least eight car-to-car or car-to-barrier tests, each solved forward with the one stated rule."""
    names = []
    for group, file in measured.FILES.items():
        cases = measured.load(group)
        measured._check_rule(cases, file)  # raises naming a case that does not hold the rule
        names += [c.name for c in cases]
    assert len(names) >= 8 and len(set(names)) == len(names)
    assert set(measured.recorded()) == set(names)


@pytest.mark.slow
def test_the_forward_values_are_their_recorded_figures(measured, measured_groups):
    recorded = measured.recorded()
    got = measured.record(measured_groups)
    assert set(got) == set(recorded)
    for case, results in got.items():
        assert set(results) == set(recorded[case]), case
        for path, value in results.items():
            assert value == pytest.approx(recorded[case][path], rel=1e-9, abs=1e-12), (case, path)


def _json_value(case, path):
    """A vehicle's result from a case of ``ks-jax solve --json``: ``vehicles[i].name`` or ``vehicles[i].name[k]``."""
    head, name = path.split(".", 1)
    vehicle = case["vehicles"][int(head[9:-1])]
    if name.endswith("]"):
        name, k = name[:-1].split("[")
        return vehicle[name][int(k)]
    return vehicle[name]


@pytest.mark.slow
def test_the_command_line_gives_the_pages_values(measured, measured_groups, capsys):
    """``ks-jax solve --json`` of every measured file gives the recorded forward values, and ``ks-jax fit --json``
    the page's fits (the same estimate and chi^2): the commands a user runs on these files reproduce the page."""
    recorded = measured.recorded()
    for group, file in measured.FILES.items():
        code, out, err = run_cli(capsys, "solve", str(measured.MEASURED / file), "--json")
        assert code == 0, err
        for case in json.loads(out)["cases"]:
            for path, value in recorded[case["name"]].items():
                assert _json_value(case, path) == pytest.approx(value, rel=1e-9, abs=1e-12), (file, path)
        code, out, err = run_cli(capsys, "fit", str(measured.MEASURED / file), "--json")
        assert code == 0, err
        fitted = {row.case: row.result for row in measured_groups[group][1]}
        for case in json.loads(out)["cases"]:
            want = fitted[case["name"]]
            assert case["chi2"] == pytest.approx(want.chi2, rel=1e-6, abs=1e-9), (file, case["name"])
            for path, value in case["estimate"].items():
                if want.std[path] < float("inf"):
                    assert value == pytest.approx(want.estimate[path], rel=1e-6, abs=1e-9), (file, path)


def test_the_barrier_tests_evidence_is_what_its_channels_give(measured):
    """The delta-V and sigma written in test 10146's case file are those ``ks_jax.measured`` reads from the shipped
    channels (to the digits written)."""
    (case,) = measured.load("ncap")
    (evidence,) = case.raw["evidence"]
    dv, _ = measured.ncap_measurements()
    assert float(evidence["value"].split()[0]) == pytest.approx(dv.magnitude, abs=5e-5)
    assert float(evidence["sigma"].split()[0]) == pytest.approx(dv.sigma, abs=5e-5)
    assert float(case.raw["reference"]["vehicles[0].delta_v_magnitude"].split()[0]) == pytest.approx(
        dv.magnitude * 3.6, abs=5e-3)
