"""docs/validation.md: every published or closed-form case is reproduced within its stated tolerance, and
the page is exactly what docs/validation.py prints, so that it cannot drift from the code."""

import importlib.util
import sys
from pathlib import Path

import pytest

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


@pytest.mark.slow
def test_every_difference_is_within_its_tolerance(validation, groups):
    compared = 0
    for group, rows in groups.items():
        for row in rows:
            assert row.within, (group, row)
            compared += 1
    assert compared >= 60, compared
    assert {g: len(r) for g, r in groups.items() if g != "wall"} == {"manual": 12, "inline": 12, "brach": 28}


def test_every_group_has_its_cases(groups):
    starts = {g: sum(1 for r in rows if r.case) for g, rows in groups.items()}
    assert starts == {"manual": 2, "inline": 3, "brach": 4, "wall": 3}


def test_the_page_is_what_the_script_prints(validation, groups):
    assert (DOCS / "validation.md").read_text() == validation.markdown(groups), (
        "docs/validation.md is stale: run python docs/validation.py --write")
