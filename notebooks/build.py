"""Build the notebooks from their sources, execute each on a fresh kernel and write it with its outputs.

Each notebook's source is the Python file of the same name beside it, in jupytext's percent format: ``# %%``
opens a code cell, ``# %% [markdown]`` a markdown cell whose lines are comments. Edit that file, then run

    python notebooks/build.py                      # every notebook
    python notebooks/build.py 02_parameter_sweeps  # only those named (stem, .py or .ipynb)
    python notebooks/build.py --no-execute         # without outputs

The notebooks are shipped executed, so that a reader browsing the repository sees the figures. A notebook
whose run fails is not written: the command names the notebook, the cell and the error, and exits with 1.
"""

import argparse
import re
import sys
import time
from pathlib import Path

import jupytext
import nbclient
import nbformat
from nbclient.exceptions import CellExecutionError, CellTimeoutError, DeadKernelError

HERE = Path(__file__).parent
FORMAT = "py:percent"
# the notebooks, by file name: one for every source NN_name.py here (this script is not one)
NOTEBOOKS = sorted(p.with_suffix(".ipynb").name for p in HERE.glob("[0-9][0-9]_*.py"))
KERNELSPEC = {"name": "python3", "display_name": "Python 3", "language": "python"}

# The kernel's options: figures inline as PNG at 110 dpi, so that legends and tick labels (8-9 pt) read at
# 12-14 pixels, and only its errors on the log (its start-up warning about unencrypted local TCP is noise in
# the command's progress). A notebook's column is about 1000-1400 pixels wide and shows a wider image scaled
# down, text and all: figures are at most 13 inches wide (11-12 for most), and the colour maps' PNGs stay
# under tests/test_notebooks.py's limit.
KERNEL_ARGUMENTS = ["--InlineBackend.rc={'figure.dpi': 110}", "--log-level=ERROR"]
# A guard against a hung kernel, not a speed target: the longest cell (08's fit with its posterior, NUTS through
# the motion to rest) takes about 7 minutes on a quiet 2-core machine and longer beside a test run's other worker
# (docs/performance.md).
CELL_TIMEOUT = 1200  # seconds


def source(name):
    """The percent file that is the source of the notebook ``name`` (a file name of ``NOTEBOOKS``)."""
    return HERE / Path(name).with_suffix(".py").name


def build(name):
    """The notebook ``name`` (a file name of ``NOTEBOOKS``) as read from its source, without outputs."""
    nb = jupytext.read(source(name), fmt=FORMAT)
    for i, cell in enumerate(nb.cells):
        cell.id = f"{Path(name).stem[:2]}-{i:02d}"   # stable ids: a rebuild changes nothing it need not
    # only the kernel: jupytext's own record of the source's format stays out of the shipped notebook
    nb.metadata = nbformat.from_dict({"kernelspec": KERNELSPEC})
    return nb


class NotebookError(Exception):
    """A notebook's run failed: the message names the notebook, the cell (index into its cells) and the error."""


ANSI = re.compile(r"\x1b\[[0-9;]*m")  # the colours of IPython's tracebacks


def execute(nb, name):
    """Run ``nb`` (the notebook ``name``) top to bottom on a fresh ``python3`` kernel in notebooks/, in place,
    and tidy it (``tidy``). A failing cell raises ``NotebookError`` with that cell's own traceback only."""
    current = {}
    client = nbclient.NotebookClient(
        nb, timeout=CELL_TIMEOUT, kernel_name=KERNELSPEC["name"], extra_arguments=KERNEL_ARGUMENTS,
        record_timing=False, resources={"metadata": {"path": str(HERE)}},
        on_cell_start=lambda cell, cell_index: current.update(index=cell_index))
    try:
        client.execute()
    except CellExecutionError as e:
        i = current["index"]
        tb = next(("\n".join(o.traceback) for o in nb.cells[i].outputs if o.output_type == "error"), e.traceback)
        raise NotebookError(f"{name}: cell {i} failed: {e.ename}: {e.evalue}\n{ANSI.sub('', tb)}") from None
    except (CellTimeoutError, DeadKernelError) as e:
        raise NotebookError(f"{name}: cell {current.get('index')} failed: {type(e).__name__}: "
                            f"{str(e).splitlines()[0]}") from None
    tidy(nb)
    return nb


def tidy(nb):
    """Keep nothing in an executed notebook that changes from one run to the next but the outputs: execution
    counts 1..n (as on a fresh kernel, whatever ran it) and no Python patch version (the kernel's)."""
    count = 0
    for cell in nb.cells:
        if cell.cell_type == "code":
            count += 1
            cell.execution_count = count
            for out in cell.outputs:
                if out.output_type == "execute_result":
                    out.execution_count = count
    nb.metadata.get("language_info", {}).pop("version", None)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", metavar="NOTEBOOK",
                        help=f"notebooks to build (default all; a stem, .py or .ipynb): {', '.join(NOTEBOOKS)}")
    parser.add_argument("--no-execute", action="store_true", help="write the notebooks without outputs")
    args = parser.parse_args(argv)
    names = [Path(n).with_suffix(".ipynb").name for n in args.names] or NOTEBOOKS
    unknown = [n for n in names if n not in NOTEBOOKS]
    if unknown:
        parser.error(f"no notebook {', '.join(unknown)}; there are {', '.join(NOTEBOOKS)}")
    failed = []
    for name in names:
        nb = build(name)
        if not args.no_execute:
            print(f"{name}: executing ...", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            try:
                execute(nb, name)
            except NotebookError as e:
                print(e, file=sys.stderr)
                print(f"{name}: not written", file=sys.stderr)
                failed.append(name)
                continue
            print(f"{name}: executed in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        nbformat.write(nb, HERE / name)
        print(f"wrote {HERE / name}", file=sys.stderr)
    if failed:
        sys.exit(f"failed: {', '.join(failed)}")


if __name__ == "__main__":
    main()
