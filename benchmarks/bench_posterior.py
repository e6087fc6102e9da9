"""Benchmark: the posterior of a six-unknown, ten-evidence reconstruction by NUTS (``fit.reconstruct(posterior=N)``).

    .venv/bin/python benchmarks/bench_posterior.py [--draws 1000] [--chains 4] [--repeats 3] [--seed 0]

The case: one random sliding oblique side impact of ``bench_fit.py``'s kind, its evidence perturbed by its sigmas;
unknowns both speeds, restitution, friction and the centroid's x and y; evidence the ten of ``fit.synthetic``.
Timed: the whole ``reconstruct`` (its fit, then ``chains`` chains x (``draws`` adaptation steps + ``draws``
draws)), first with the compile, then ``repeats`` times after it (median), with another seed each time so that
nothing is reused but the compiled program; beside it the fit alone (``posterior=0``). Printed with the
posterior's R-hat, ESS and divergences and the Laplace standard errors beside the posterior's. The goal on the
2-core CPU: 4 chains x 1000 draws under 30 s after the compile.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).parent))

import fit
from bench_fit import sliding_cases


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--chains", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    cases, truths, evidence, unknowns, _ = sliding_cases(1, args.seed)
    run = lambda draws, seed: fit.reconstruct(cases[0], unknowns[0], evidence[0], posterior=draws,  # noqa: E731
                                              chains=args.chains, seed=seed)
    t = time.perf_counter()
    run(args.draws, args.seed)
    first = time.perf_counter() - t
    run(0, args.seed)
    times, fits = [], []
    for k in range(args.repeats):
        t = time.perf_counter()
        result = run(args.draws, args.seed + 1 + k)
        times.append(time.perf_counter() - t)
        t = time.perf_counter()
        run(0, args.seed + 1 + k)
        fits.append(time.perf_counter() - t)
    print(f"bench_posterior: {args.chains} chains x {args.draws} draws (+ {args.draws} adaptation steps), "
          f"{len(unknowns[0])} unknowns, {len(evidence[0])} evidence, float64")
    print(f"  {datetime.date.today()}, {platform.node()}, {jax.devices()[0].device_kind}, {os.cpu_count()} CPUs, "
          f"jax {jax.__version__}; {' '.join([os.path.basename(sys.argv[0])] + (argv or sys.argv[1:]))}")
    print(f"  fit and posterior: {statistics.median(times):.2f} s after the compile (median of {args.repeats}; "
          f"first call {first:.1f} s); the fit alone {statistics.median(fits):.2f} s")
    post = result.posterior
    print(f"  divergences {post.divergences}; warnings: {post.warnings or 'none'}")
    for path, s in post.summary.items():
        print(f"  {path:22s} estimate {result.estimate[path]:10.4f} +/- {result.std[path]:.4f} (Laplace)   posterior "
              f"{s['mean']:10.4f} +/- {s['std']:.4f}   R-hat {s['rhat']:.4f}   ESS {s['ess']:6.0f}")


if __name__ == "__main__":
    main()
