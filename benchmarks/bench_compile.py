"""Compile time and run time of the programs ``quick_jit`` compiles, with the quick options of JAX's default
backend (``ks_jax.compilation.quick_options``: ``QUICK_CPU`` on a CPU, ``QUICK_GPU`` on a GPU) against XLA's
defaults. Not a test.

    .venv/bin/python benchmarks/bench_compile.py [--rounds 5] [--large]

The programs are the ones the command line compiles: ``ks_jax.solve`` of the seed case (given contact) and
of ``auto_seed_000.json`` (automatic contact) and of ``rest_seed_000.json`` (with the motion to rest), and the
solver of ``fit.reconstruct`` of ``fit_seed_001.json`` (its cases x starts in one call). ``--large`` adds the
solver of ``fit.reconstruct_batch`` of 1000 of ``bench_fit.py``'s cases x 8 starts (8000 rows in one call), which
compiles with XLA's defaults (above ``fit.rows.QUICK_ROWS``): whether the quick options would cost it run time.
Every round traces, lowers and compiles each program both ways, the order alternating, and times the compile
only; then one call of each compiled program is timed (median of 20; of 5 for the 8000 rows).
Prints every round and the medians of the ratios within rounds. Nothing is kept between processes.
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

import bench_fit
import fit
import fit.rows
import ks_jax
from ks_jax.compilation import quick_options

CASES = Path(ks_jax.__file__).parent / "cases"
LARGE = "fit (8000 rows)"  # --large's program: its calls take seconds on a CPU, so 5 are timed, not 20


def captured_calls(large: bool = False, plan=None):
    """{name: (quick_jit function, args)} of the programs, recorded from one solve or fit each on ``plan`` (default:
    the default devices' path)."""
    calls = {}
    solve_module = importlib.import_module("ks_jax.solve.cases")  # the module of ks_jax.solve, the function
    original = solve_module._solve

    def recording(name, fun):
        def call(*args):
            calls[name] = (fun, args)
            return fun(*args)
        return call

    for name, case in (("solve", "seed_000_saturn_pontiac.json"), ("solve (automatic)", "auto_seed_000.json"),
                       ("solve (to rest)", "rest_seed_000.json")):
        solve_module._solve = recording(name, original)
        ks_jax.solve(ks_jax.load_case(CASES / case), plan=plan)
    solve_module._solve = original

    pick = fit.rows.solver_for
    fit.rows.solver_for = lambda block, devices: recording("fit", fit.rows.fit_rows)
    fit.reconstruct(ks_jax.load_cases(CASES / "fit_seed_001.json")[0], plan=plan)
    if large:
        cases, _, evidence, unknowns, _ = bench_fit.sliding_cases(1000, 0)
        fit.rows.solver_for = lambda block, devices: recording(LARGE, fit.rows.fit_rows)
        fit.reconstruct_batch(cases, unknowns, evidence, starts=8, max_starts=8, smoothing=bench_fit.SMOOTHING,
                              plan=plan)
    fit.rows.solver_for = pick
    return calls


def compile_seconds(jitted, args):
    """Seconds to compile the lowered program: lowered anew, as a lowered program keeps its executable."""
    jax.clear_caches()
    lowered = jitted.lower(*args)
    return timed(lowered.compile)


def timed(fun, *args):
    start = time.perf_counter()
    jax.block_until_ready(fun(*args))
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--large", action="store_true", help="also the fit's solver of 8000 rows (1000 x 8)")
    a = parser.parse_args()
    print(f"bench_compile.py --rounds {a.rounds}")
    print(f"  date     {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC")
    print(f"  machine  {platform.processor() or platform.machine()}, {os.cpu_count()} cores; jax {jax.__version__}")
    print(f"  backend  {jax.default_backend()} ({jax.devices()[0].device_kind}); quick options "
          f"{quick_options()}")
    for name, (fun, args) in captured_calls(a.large).items():
        ways = {"quick": fun.quick.jitted, "defaults": fun.plain.jitted}
        ratios, runs, compiles = [], [], {w: [] for w in ways}
        for k in range(a.rounds):
            order = list(ways) if k % 2 == 0 else list(ways)[::-1]
            seconds = {way: compile_seconds(ways[way], args) for way in order}
            for way in order:
                compiles[way].append(seconds[way])
            ratios.append(seconds["defaults"] / seconds["quick"])
            print(f"  {name:18s} round {k}: compile quick {seconds['quick']:.2f} s, "
                  f"defaults {seconds['defaults']:.2f} s")
        for way in ways:
            jitted = ways[way]
            jitted(*args)
            runs.append(statistics.median(timed(jitted, *args) for _ in range(5 if name == LARGE else 20)))
        print(f"{name:18s} compile: quick {statistics.median(compiles['quick']):.2f} s, defaults "
              f"{statistics.median(compiles['defaults']):.2f} s, defaults / quick {statistics.median(ratios):.2f}; "
              f"one call: quick {runs[0] * 1e3:.2f} ms, defaults {runs[1] * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
