"""Seconds of each ``ks-jax fit`` run of tests/command_matrix.py on one case file, each run twice in one process:
the first run traces and compiles its programs, the second runs them compiled (what is left is execution).

    .venv/bin/python benchmarks/fit_commands.py ks_jax/cases/fit_rest_positions.json
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import time

os.environ.setdefault("KS_JAX_CACHE", "off")  # nothing kept between processes: every first run compiles

import jax

from ks_jax.cli import main

jax.config.update("jax_enable_x64", True)  # as the tests run it

RUNS = ([], ["--monte-carlo", "20"], ["--posterior", "6", "--chains", "2", "--json"])

if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: fit_commands.py CASE_FILE")
    for extra in RUNS:
        seconds = []
        for _ in range(2):
            start = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                main(["fit", sys.argv[1], *extra])
            seconds.append(time.perf_counter() - start)
        print(f"fit {' '.join(extra) or '(the report)':32s} first {seconds[0]:6.1f} s   again {seconds[1]:6.1f} s")
