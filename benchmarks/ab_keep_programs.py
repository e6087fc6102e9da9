"""A new Python process (a notebook after a restart) without ``ks_jax.keep_programs``, with JAX's compiled
programs kept only, and with the traced programs kept too. Not a test.

    .venv/bin/python benchmarks/ab_keep_programs.py fit|batch [--rounds 3]

``fit``: seconds from ``import jax`` to the end of ``fit.reconstruct`` of ``fit_seed_001.json``, then of
``ks_jax.solve`` of ``auto_seed_000.json`` after it. ``batch``: from ``import jax`` to the end of
``ks_jax.exchange_batch`` over 2^16 rows of the seed case (the bullet car's speed varied), then that call
alone. Three ways, each in fresh processes: ``none`` (nothing kept), ``compiled`` (``keep_programs`` to a
folder of its own, then ``ks_jax.compilation._FOLDER = None``: JAX's compiled programs kept, the traced
programs of ``quick_jit`` not) and ``traced`` (``keep_programs``: both; the traced ones need the ``cache``
extra). Each folder is filled by one run first; then --rounds rounds run the three ways in turn. Prints
every run and the medians.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parent.parent


def child(what: str, folder: str, way: str) -> None:
    start = time.perf_counter()
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import ks_jax
    from ks_jax import compilation
    from ks_jax.case import as_arrays, to_pytrees

    if way != "none":
        ks_jax.keep_programs(folder)
    if way == "compiled":
        compilation._FOLDER = None
    cases = CHECKOUT / "ks_jax" / "cases"
    if what == "fit":
        import fit

        fit.reconstruct(ks_jax.load_cases(cases / "fit_seed_001.json")[0])
        middle = time.perf_counter()
        ks_jax.solve(ks_jax.load_case(cases / "auto_seed_000.json"))
        end = time.perf_counter()
        print(f"{middle - start:.3f} {end - middle:.3f}")
    else:
        case = ks_jax.load_case(cases / "seed_000_saturn_pontiac.json")
        rows = jax.tree_util.tree_map(lambda x: np.repeat(np.asarray(x)[None], 1 << 16, axis=0),
                                      to_pytrees(as_arrays(case.inputs)))
        rows[3].velocity[:, 0] = np.linspace(5.0, 25.0, 1 << 16)
        middle = time.perf_counter()
        ks_jax.exchange_batch(*rows)
        end = time.perf_counter()
        print(f"{end - start:.3f} {end - middle:.3f}")


def run(what: str, folder: str, way: str) -> tuple[float, float]:
    done = subprocess.run([sys.executable, __file__, what, "--child", folder, way], cwd=CHECKOUT,
                          env=dict(os.environ, KS_JAX_CACHE="off"), capture_output=True, text=True, check=False)
    if done.returncode:
        raise SystemExit(f"{what} {way} failed:\n{done.stderr}")
    first, second = done.stdout.split()[-2:]
    return float(first), float(second)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["fit", "batch"])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--child", nargs=2, metavar=("FOLDER", "WAY"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args.what, *args.child)
    labels = {"fit": ("import to the end of fit.reconstruct", "the solve after it"),
              "batch": ("import to the end of exchange_batch", "exchange_batch alone")}[args.what]
    print(f"keep_programs, {args.what}: seconds ({labels[0]}; {labels[1]}), {args.rounds} rounds, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    ways = ("none", "compiled", "traced")
    with tempfile.TemporaryDirectory() as tmp:
        folders = {way: os.path.join(tmp, way) for way in ways}
        for way in ways[1:]:
            run(args.what, folders[way], way)  # fill the folder
        times = {way: [] for way in ways}
        for _ in range(args.rounds):
            for way in ways:
                times[way].append(run(args.what, folders[way], way))
    for way in ways:
        runs = ", ".join(f"{a:.2f}; {b:.2f}" for a, b in times[way])
        print(f"  {way:9} {runs}   medians {statistics.median(a for a, _ in times[way]):.2f}; "
              f"{statistics.median(b for _, b in times[way]):.2f}")


if __name__ == "__main__":
    main()
