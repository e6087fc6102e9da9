"""The notebooks: each runs top to bottom on a fresh kernel, is what ``notebooks/build.py`` makes of its cells,
and is committed executed (outputs and figures kept, so that a reader browsing the repository sees them)."""

import base64
import importlib.util
import json
import os
import re
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(HERE.glob("*.ipynb"))
IDS = [p.stem for p in NOTEBOOKS]

IMAGE_LIMIT = 150_000      # bytes of one decoded PNG (build.py draws at 80 dpi: the largest is about 125 KB)
NOTEBOOK_LIMIT = 1_000_000  # bytes of one .ipynb file
# a code cell that calls one of these draws a figure, which an executed notebook shows as a PNG
DRAWS = re.compile(r"\b(plt\.subplots|plt\.figure|top_view|sweep_view)\(")


@pytest.fixture(scope="module")
def build():
    """notebooks/build.py as a module (it is a script, not part of the package)."""
    pytest.importorskip("nbformat")
    pytest.importorskip("nbclient")
    spec = importlib.util.spec_from_file_location("build_notebooks", HERE / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_notebook_runs(path, build, monkeypatch):
    """The committed notebook runs on a fresh kernel as ``build.py`` runs it; a failing cell fails here
    with the notebook, the cell index and the cell's error."""
    nbformat = pytest.importorskip("nbformat")
    # the kernel (a subprocess) compiles into the run's shared compile cache (tests/conftest.py): the
    # notebooks build several of the same programs
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", os.environ["KS_JAX_TEST_COMPILE_CACHE"])
    monkeypatch.setenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    nb = nbformat.read(path, as_version=4)
    try:
        build.execute(nb, path.name)
    except build.NotebookError as e:
        pytest.fail(str(e), pytrace=False)


def test_notebooks_are_built_from_build_py(build):
    """The committed notebooks are what ``notebooks/build.py`` makes of its cells (edit build.py, then
    run it): a cell edited in one place only fails here. Outputs are not compared."""
    nbformat = pytest.importorskip("nbformat")
    assert sorted(build.NOTEBOOKS) == [p.name for p in NOTEBOOKS]
    for path in NOTEBOOKS:
        committed, built = nbformat.read(path, as_version=4), build.build(path.name)
        cells = [[(c.cell_type, c.source) for c in nb.cells] for nb in (committed, built)]
        assert cells[0] == cells[1], path.name


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_notebook_is_shipped_executed(path):
    """The committed notebook carries the outputs of one clean run (``python notebooks/build.py``, not
    ``--no-execute``): execution counts 1..n, no errors, no run timings, a PNG for every cell that draws, and
    images and file of a size that a repository and a browser take in."""
    assert path.stat().st_size < NOTEBOOK_LIMIT, f"{path.name}: {path.stat().st_size} bytes"
    code = [c for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code"]
    assert [c["execution_count"] for c in code] == list(range(1, len(code) + 1)), \
        f"{path.name} is not executed: run python notebooks/build.py {path.name}"
    for i, cell in enumerate(code, 1):
        where = f"{path.name}, code cell [{i}]"
        assert "execution" not in cell["metadata"], where
        assert not [o for o in cell["outputs"] if o["output_type"] == "error"], where
        images = [base64.b64decode(o["data"]["image/png"]) for o in cell["outputs"]
                  if "image/png" in o.get("data", {})]
        if DRAWS.search("".join(cell["source"])):
            assert images, f"{where} draws but has no image/png output"
        for png in images:
            assert len(png) < IMAGE_LIMIT, f"{where}: a {len(png)}-byte PNG"
