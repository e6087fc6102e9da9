"""Wall time of ``ks-jax`` commands, side by side: this checkout against another one (``--before DIR``, a
clean clone of an earlier commit), processes alternated, each side with a cache folder of its own.

    python benchmarks/ab_command_line.py --before /tmp/base --rounds 3            # warm caches
    python benchmarks/ab_command_line.py --before /tmp/base --rounds 3 --cold     # an empty cache per run

``--cold``: every run gets a new, empty ``KS_JAX_CACHE`` (what a command's first run costs); otherwise each
side's folder is filled by one run first, and the rounds read from it. Prints seconds per run, before / after.
"""

from __future__ import annotations

import argparse
import os
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
            print(f"  {name:<11} before " + " ".join(f"{t:.2f}" for t in times["before"])
                  + "   after " + " ".join(f"{t:.2f}" for t in times["after"]) + " s")


if __name__ == "__main__":
    main()
