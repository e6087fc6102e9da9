"""Seconds to trace and lower, and to compile, the program ``ks-jax solve`` builds for one shipped case (its cases
solved alone, with the quick settings on a CPU), and the size of its StableHLO: the per-program cost that the test
suite pays for every program it builds. Not a test.

    .venv/bin/python benchmarks/bench_trace.py [--case tbone_spin_out.json] [--rounds 3]

Every round frees every program (``ks_jax.free_programs``), then traces and lowers the program anew and compiles
it; the medians of the rounds are printed, with one call's seconds once compiled. The default case has a road: its
program holds the watched motion after the first exchange (docs/model.md, "Contact interactions"). To compare two
versions of the code, run it in each, one after the other, on a quiet machine.
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import os
import platform
import statistics
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import ks_jax
from ks_jax.compilation import free_programs

CASES = Path(ks_jax.__file__).parent / "cases"


def solve_call(case_file: str):
    """(the quick jitted program of ``ks_jax.solve``'s rows, its arguments) for the case file's cases."""
    module = importlib.import_module("ks_jax.solve.cases")  # the module of ks_jax.solve, the function
    original, calls = module._solve, []

    def recording(*args):
        calls.append(args)
        return original(*args)

    module._solve = recording
    try:
        ks_jax.solve(ks_jax.load_cases(CASES / case_file))
    finally:
        module._solve = original
    return original.quick.jitted, calls[0]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="tbone_spin_out.json", help="a file of ks_jax/cases/")
    parser.add_argument("--rounds", type=int, default=3)
    a = parser.parse_args(argv)
    jitted, args = solve_call(a.case)
    arrays = args[:1]  # the inputs; the rest are static
    lowering, compiling, size = [], [], 0
    for _ in range(a.rounds):
        free_programs()
        start = time.perf_counter()
        lowered = jitted.lower(*args)
        lowering.append(time.perf_counter() - start)
        size = len(lowered.as_text())
        start = time.perf_counter()
        compiled = lowered.compile()
        compiling.append(time.perf_counter() - start)
    jax.block_until_ready(compiled(*arrays))
    start = time.perf_counter()
    jax.block_until_ready(compiled(*arrays))
    call = time.perf_counter() - start
    print(f"bench_trace.py --case {a.case} --rounds {a.rounds}")
    print(f"  {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {platform.node()}, "
          f"{os.cpu_count()} CPUs, jax {jax.__version__}")
    print(f"  trace and lower {statistics.median(lowering):.2f} s, compile {statistics.median(compiling):.2f} s "
          f"(medians), StableHLO {size / 1e6:.2f} MB, one call {call * 1e3:.1f} ms")
    print("  rounds: " + ", ".join(f"{lo:.2f} + {c:.2f} s" for lo, c in zip(lowering, compiling)))


if __name__ == "__main__":
    main()
