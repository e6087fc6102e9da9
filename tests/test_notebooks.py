"""Every notebook runs top to bottom on a fresh kernel (outputs are stripped in the repository)."""

import os
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    # the kernel (a subprocess) compiles into the run's shared compile cache (tests/conftest.py): the
    # notebooks build several of the same programs
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", os.environ["KS_JAX_TEST_COMPILE_CACHE"])
    monkeypatch.setenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors


def test_notebooks_are_built_from_build_py():
    """The committed notebooks are what ``notebooks/build.py`` makes of its cells (edit build.py, then
    run it): a cell edited in one place only fails here."""
    nbformat = pytest.importorskip("nbformat")
    import importlib.util

    spec = importlib.util.spec_from_file_location("build_notebooks", NOTEBOOKS[0].parent / "build.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    assert sorted(build.NOTEBOOKS) == [p.name for p in NOTEBOOKS]
    for path in NOTEBOOKS:
        committed, built = nbformat.read(path, as_version=4), build.build(path.name)
        cells = [[(c.cell_type, c.source) for c in nb.cells] for nb in (committed, built)]
        assert cells[0] == cells[1], path.name
