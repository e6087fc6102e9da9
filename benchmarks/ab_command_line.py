"""Wall time of ``ks-jax`` commands, side by side: this checkout against another one (``--before DIR``, a
clean clone of an earlier commit), processes alternated, each side with a cache folder of its own.

    .venv/bin/python benchmarks/ab_command_line.py --before /tmp/before --rounds 3          # warm caches
    .venv/bin/python benchmarks/ab_command_line.py --before /tmp/before --rounds 3 --cold   # an empty cache per run

Each run is ``python -m ks_jax.cli ...`` in the checkout, with the checkout first on ``PYTHONPATH`` (checked
before the runs: ``ks_jax`` and ``fit`` are imported from it, not from an installed copy). Commands: ``solve``
of the seed case, ``solve`` of the automatic-contact case, ``demo``, ``fit`` of the shipped reconstruction and
a 41 x 7 ``sweep`` of the automatic-contact T-bone into a .csv. ``--cold``: every run gets a new, empty
``KS_JAX_CACHE`` (what a command's first run costs); otherwise each side's folder is filled by one run first,
and the rounds read from it. Prints the seconds of every run, the medians and after / before.
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

HERE = Path(__file__).resolve().parent.parent
COMMANDS = {
    "solve": ["solve", "ks_jax/cases/seed_000_saturn_pontiac.json"],
    "solve-auto": ["solve", "ks_jax/cases/auto_seed_000.json"],
    "demo": ["demo"],
    "fit": ["fit", "ks_jax/cases/fit_seed_001.json"],
    "sweep-auto": ["sweep", "ks_jax/cases/auto_tbone.json", "--over", "vehicles[1].speed=20mph:40mph:41",
                   "--over", "contact.restitution=0:0.3:7", "--out", "{tmp}/sweep.csv", "--no-progress"],
}


def run(checkout: Path, argv, cache: str, tmp: str) -> float:
    env = dict(os.environ, KS_JAX_CACHE=cache, PYTHONPATH=str(checkout))
    argv = [a.replace("{tmp}", tmp) for a in argv]
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "ks_jax.cli", *argv], cwd=checkout, env=env,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seconds = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{checkout}: ks-jax {' '.join(argv)} failed:\n{done.stderr}")
    return seconds


def check_imports(checkout: Path) -> None:
    """Stop unless a process run as ``run`` runs imports ``ks_jax`` and ``fit`` from ``checkout``."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    code = "import ks_jax, fit; print(ks_jax.__file__); print(fit.__file__)"
    done = subprocess.run([sys.executable, "-c", code], cwd=checkout, env=env, capture_output=True, text=True)
    files = done.stdout.split()
    if done.returncode or len(files) != 2 or not all(Path(f).resolve().is_relative_to(checkout) for f in files):
        raise SystemExit(f"{checkout}: ks_jax and fit are not imported from it: {done.stdout}{done.stderr}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, type=Path, help="checkout of the earlier commit")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--cold", action="store_true", help="an empty cache for every run")
    parser.add_argument("--only", nargs="*", choices=sorted(COMMANDS), help="these commands (default: all)")
    args = parser.parse_args()
    sides = {"before": args.before.resolve(), "after": HERE}
    print(f"ks-jax commands, {'empty caches' if args.cold else 'warm caches'}, {args.rounds} rounds, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; before = {sides['before']}, after = {HERE}")
    for checkout in sides.values():
        check_imports(checkout)
    with tempfile.TemporaryDirectory() as tmp:
        caches = {side: os.path.join(tmp, side) for side in sides}
        for name in args.only or COMMANDS:
            argv = COMMANDS[name]
            if not args.cold:
                for side, checkout in sides.items():
                    run(checkout, argv, caches[side], tmp)
            times = {side: [] for side in sides}
            for _ in range(args.rounds):
                for side, checkout in sides.items():
                    cache = tempfile.mkdtemp(dir=tmp) if args.cold else caches[side]
                    times[side].append(run(checkout, argv, cache, tmp))
            medians = {side: statistics.median(ts) for side, ts in times.items()}
            print(f"  {name:<11} before " + " ".join(f"{t:.2f}" for t in times["before"])
                  + "   after " + " ".join(f"{t:.2f}" for t in times["after"])
                  + f" s; medians {medians['before']:.2f} / {medians['after']:.2f} s, after/before "
                  f"{medians['after'] / medians['before']:.2f}", flush=True)


if __name__ == "__main__":
    main()
