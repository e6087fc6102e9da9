"""The command matrix (``command_matrix``: every command on every case the project ships) checks something: the
documented keys are read, every kind of source is in it, and its groups, a test file each (``test_matrix_*.py``),
hold every source once."""

from __future__ import annotations

from pathlib import Path

from command_matrix import BLOCKS, FILES, FITTED, GROUPS, KEYS, NOT_CASES, SOURCES


def test_the_documented_keys_are_read():
    """The matrix checks something: docs/model.md names keys for the solved case, its contact and vehicles, and
    the fitted case."""
    assert {"point", "impulse", "energy_loss", "status"} <= KEYS["contact"]
    assert {"delta_v", "pdof", "pdof_clock", "ees"} <= KEYS["vehicle"]
    assert {"rest_position", "at_rest"} <= KEYS["rest"]
    assert {"estimate", "std", "chi2", "converged", "notes"} <= KEYS["fitted case"]


def test_every_shipped_case_is_in_the_matrix():
    """The matrix is not empty: the package's cases, the docs' example and validation files and the docs'
    case blocks, among them a reconstruction."""
    assert len(FILES) >= 14 and any(s.startswith("docs/model.md#") for s in SOURCES)
    assert any(s.startswith("docs/") and s in FITTED for s in SOURCES)
    assert any(s.startswith("docs/validation/measured/") for s in SOURCES)
    assert all(p.is_file() for p in NOT_CASES)


def test_the_groups_hold_every_source_once_and_each_has_its_file():
    """A source in no group would be run by no test, one in two groups twice."""
    for source in SOURCES:
        assert sum(member(source) for member in GROUPS.values()) == 1, source
    assert all(any(member(s) for s in SOURCES) for member in GROUPS.values())
    here = Path(__file__).parent
    assert sorted(p.name for p in here.glob("test_matrix_*.py")) == sorted(f"test_matrix_{g}.py" for g in GROUPS)
    assert BLOCKS and set(BLOCKS) <= set(SOURCES)
