"""What `--plot` adds to a 10^6-point sweep from the command line: wall time and peak memory. Not a test.

    .venv/bin/python benchmarks/bench_sweep_plot.py [--tree DIR ...] [--rounds 3] [--n 1000]

Runs `ks-jax sweep` on an n x n grid of the manual's Lucid-Kia crash, ks_jax/cases/seed_001_lucid_kia.toml (speed x
restitution, the default outputs, written to .npz) without and with `--plot`, each in a fresh process, rounds
interleaved, after one warm-up run per tree (so that every timed run loads its programs from the kept programs). Each
`--tree` is a checkout of the project (default: this one), run with PYTHONPATH set to it: two trees compare two versions
side by side (`git worktree add /tmp/before HEAD~1`). Prints per tree the medians of wall time and peak resident memory
(the child's ru_maxrss), and the ratio with / without the picture.
"""

import argparse
import datetime
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(tree, n, folder, plot):
    """(wall seconds, peak RSS MiB) of one `ks-jax sweep` in a fresh process."""
    case = Path(tree) / "ks_jax" / "cases" / "seed_001_lucid_kia.toml"
    argv = [sys.executable, "-m", "ks_jax.cli", "sweep", str(case), "--over", f"vehicles[1].speed=10mph:60mph:{n}",
            "--over", f"contact.restitution=0:0.5:{n}", "--out", str(Path(folder) / "r.npz"), "--no-progress"]
    if plot:
        argv += ["--plot", str(Path(folder) / "r.png")]
    env = dict(os.environ, PYTHONPATH=str(tree))
    start = time.perf_counter()
    # run in the tree: `python -m` puts the working directory first on the path, before PYTHONPATH
    child = subprocess.Popen(argv, env=env, cwd=tree, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - start
    if status != 0:
        raise SystemExit(f"{tree}: ks-jax sweep failed: {child.stderr.read().decode()[-2000:]}")
    return seconds, usage.ru_maxrss / 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tree", action="append", help="a checkout to run (repeat; default: this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--n", type=int, default=1000, help="values per axis (n x n points)")
    args = ap.parse_args()
    trees = args.tree or [str(ROOT)]
    print(f"# {datetime.date.today()}, {platform.node()}, {os.cpu_count()} CPUs; python {' '.join(sys.argv)}")
    print(f"# ks-jax sweep of {args.n} x {args.n} = {args.n**2:,} points, default outputs, .npz; medians of "
          f"{args.rounds} rounds")
    times = {(t, p): [] for t in trees for p in (False, True)}
    with tempfile.TemporaryDirectory() as folder:
        for tree in trees:
            run(tree, args.n, folder, True)  # warm-up: compiles and keeps the programs
        for _ in range(args.rounds):
            for tree in trees:
                for plot in (False, True):
                    times[tree, plot].append(run(tree, args.n, folder, plot))
    for tree in trees:
        (t0, m0), (t1, m1) = ([statistics.median(x[k] for x in times[tree, p]) for k in (0, 1)] for p in (False, True))
        print(f"{tree}: without --plot {t0:.2f} s, {m0:.0f} MiB; with --plot {t1:.2f} s, {m1:.0f} MiB; "
              f"--plot adds {t1 - t0:+.2f} s ({t1 / t0:.2f}x), {m1 - m0:+.0f} MiB ({m1 / m0:.2f}x)")


if __name__ == "__main__":
    main()
