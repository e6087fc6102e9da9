"""The notebooks: each runs top to bottom on a fresh kernel, has the cells of its source (the percent file
beside it, which ``notebooks/build.py`` builds it from), and is committed executed (outputs and figures kept, so
that a reader browsing the repository sees them)."""

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

IMAGE_LIMIT = 175_000      # bytes of one decoded PNG (build.py draws at 110 dpi: the largest, 05's top views with
# their later exchanges marked, are about 156 and 161 KB)
NOTEBOOK_LIMIT = 1_000_000  # bytes of one .ipynb file
# a code cell that calls one of these draws a figure, which an executed notebook shows as a PNG
DRAWS = re.compile(r"\b(plt\.subplots|plt\.figure|top_view|sweep_view)\(")


@pytest.fixture(scope="module")
def build():
    """notebooks/build.py as a module (it is a script, not part of the package)."""
    pytest.importorskip("nbformat")
    pytest.importorskip("nbclient")
    pytest.importorskip("jupytext")
    spec = importlib.util.spec_from_file_location("build_notebooks", HERE / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_notebook_runs(path, build, monkeypatch):
    """The notebook's source runs on a fresh kernel as ``build.py`` runs it; a failing cell fails here with the
    notebook, the cell index and the cell's error."""
    # the kernel (a subprocess) compiles into the run's shared compile cache (tests/conftest.py): the
    # notebooks build several of the same programs
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", os.environ["KS_JAX_TEST_COMPILE_CACHE"])
    monkeypatch.setenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    try:
        build.execute(build.build(path.name), path.name)
    except build.NotebookError as e:
        pytest.fail(str(e), pytrace=False)


def test_notebooks_are_built_from_their_sources():
    """Each committed notebook's cells (types and sources) are those of its percent file (edit the .py, then run
    ``python notebooks/build.py NAME``): a cell edited in one place only fails here. Outputs are not compared."""
    nbformat = pytest.importorskip("nbformat")
    jupytext = pytest.importorskip("jupytext")
    sources = sorted(HERE.glob("[0-9][0-9]_*.py"))
    assert [p.stem for p in sources] == IDS
    for path, src in zip(NOTEBOOKS, sources):
        committed, source = nbformat.read(path, as_version=4), jupytext.read(src, fmt="py:percent")
        cells = [[(c.cell_type, c.source) for c in nb.cells] for nb in (committed, source)]
        assert cells[0] == cells[1], \
            f"{path.name} is not built from {src.name}: run python notebooks/build.py {path.stem}"


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
