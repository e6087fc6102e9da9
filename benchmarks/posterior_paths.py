"""How the posterior tests' checks fare over many chain paths: the problems of ``tests/fit/test_posterior.py``
drawn with many seeds, each seed a different path, as another machine's rounding gives. Not a test.

    .venv/bin/python benchmarks/posterior_paths.py [--seeds 100] [--draws 1000] [--targets 0.8 0.9] [--one-draws 500]

The problems: the seed chapter's rear impact (``fit_seed_001.json``) refitted from its own delta-Vs and speeds after
(sigma 0.15 m/s each), the Kia's speed and the restitution unknown (bounds [0, 30] m/s and [0, 0.6]); the truth's
restitution 0.3 (the posterior is the Laplace Gaussian) or 0 (on its bound: a half-normal of the Laplace standard
error). 4 chains x ``--draws`` draws after as many adaptation steps, toward each target acceptance.

Printed per problem and target: the seeds whose chains diverged and their most divergent transitions, the largest
R-hat and smallest ESS over every unknown, and each check's largest error in Monte Carlo standard errors (the
tests allow 4) with the seeds above 4: the mean and std against the Laplace Gaussian's, and the 16-84% span
against two standard errors (a relative error; the test allows 0.1); at the bound, the mean,
std (its error from the half-normal's fourth moment), median and 97.5% quantile against the half-normal's.

Then the one-unknown problem: the Kia's speed from an EDR's 9 m/s (sigma 0.3) and a Gaussian prior of 9.6 +/- 0.4
m/s, whose posterior is a Gaussian in closed form; 2 chains and 1 chain x ``--one-draws`` draws at Stan's target
acceptance: the smallest ESS (the tests ask above 50), the largest R-hat of two chains (the test asks below 1.05),
and the largest error of the mean, std and median in Monte Carlo standard errors.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import math
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import fit
from ks_jax.case import get_output, load_case, set_input
from ks_jax.solve import solve

CASE = Path(__file__).resolve().parents[1] / "ks_jax" / "cases" / "fit_seed_001.json"
EVIDENCE = ["vehicles[0].delta_v_magnitude", "vehicles[1].delta_v_magnitude", "vehicles[0].speed_after",
            "vehicles[1].speed_after"]
SIGMA = 0.15
RESTITUTION = "contact.restitution"


def problem(restitution: float):
    """The case at ``restitution``, its noise-free evidence, and the two unknowns."""
    case = load_case(CASE)
    case = dataclasses.replace(case, inputs=set_input(case.inputs, RESTITUTION, restitution))
    result = solve(case, smoothing=1e-3).result
    evidence = [fit.Evidence(p, float(get_output(result, p)), SIGMA) for p in EVIDENCE]
    unknowns = [fit.Unknown("vehicles[1].speed", 0.0, 30.0), fit.Unknown(RESTITUTION, 0.0, 0.6)]
    return case, unknowns, evidence


def gaussian_errors(r) -> dict:
    """Each unknown's posterior mean and std against the estimate and the Laplace standard error, in Monte Carlo
    standard errors (std / sqrt(ESS), std / sqrt(2 ESS)), and its 16-84% span over two standard errors, less 1."""
    out = {}
    for path, s in r.posterior.summary.items():
        se = r.std[path]
        out[f"mean {path}"] = abs(s["mean"] - r.estimate[path]) / (s["std"] / math.sqrt(s["ess"]))
        out[f"std {path}"] = abs(s["std"] - se) / (se / math.sqrt(2 * s["ess"]))
        out[f"span {path}"] = abs((s["q84"] - s["q16"]) / (2 * se) - 1)
    return out


def half_normal_errors(r) -> dict:
    """The restitution's posterior against the half-normal of the Laplace standard error sigma, in Monte Carlo
    standard errors: mean, std (from the fourth central moment mu4), median and 97.5% quantile (sqrt(p (1 - p) /
    ESS) over the density at the quantile)."""
    sigma, s = r.std[RESTITUTION], r.posterior.summary[RESTITUTION]
    ess = s["ess"]
    var, mu4 = (1 - 2 / math.pi) * sigma ** 2, (3 - 4 / math.pi - 12 / math.pi ** 2) * sigma ** 4
    out = {"mean": abs(s["mean"] - sigma * math.sqrt(2 / math.pi)) / (s["std"] / math.sqrt(ess)),
           "std": abs(s["std"] - math.sqrt(var)) / math.sqrt((mu4 - var * var) / (4 * var * ess))}
    for key, p, z in (("q50", 0.5, 0.6745), ("q975", 0.975, 2.2414)):
        density = 2 * math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) / sigma
        out[key] = abs(s[key] - z * sigma) / (math.sqrt(p * (1 - p) / ess) / density)
    return out


def paths(restitution: float, target: float, seeds: int, draws: int) -> None:
    case, unknowns, evidence = problem(restitution)
    errors = half_normal_errors if restitution == 0.0 else gaussian_errors
    diverged, rhat, ess, worst, seconds = {}, [], [], {}, []
    for seed in range(seeds):
        t0 = time.perf_counter()
        r = fit.reconstruct(case, unknowns, evidence, posterior=draws, seed=seed, target_acceptance=target)
        seconds.append(time.perf_counter() - t0)
        post = r.posterior
        if post.divergences:
            diverged[seed] = post.divergences
        rhat += [s["rhat"] for s in post.summary.values()]
        ess += [s["ess"] for s in post.summary.values()]
        for check, z in errors(r).items():
            worst.setdefault(check, []).append((z, seed))
    kind = "on its bound (half-normal)" if restitution == 0.0 else f"{restitution} (Gaussian)"
    print(f"\nrestitution {kind}, target acceptance {target}, {seeds} seeds x 4 chains x {draws} draws "
          f"(median {np.median(seconds[1:] or seconds):.2f} s a fit and posterior after the first)")
    print(f"  seeds whose chains diverged: {len(diverged)}"
          + (f" (most: {max(diverged.values())} transitions, seed {max(diverged, key=diverged.get)})" if diverged
             else ""))
    print(f"  R-hat at most {max(rhat):.4f}; ESS at least {min(ess):.0f}")
    for check, values in worst.items():
        z, seed = max(values)
        limit = 0.1 if check.startswith("span") else 4
        above = [s for v, s in values if v > limit]
        print(f"  {check}: largest error {z:.3g} (seed {seed}); above {limit:g}: {len(above)}"
              + (f" {above}" if above else ""))


def one_unknown_paths(seeds: int, draws: int) -> None:
    case = load_case(CASE)
    edr, edr_sigma, prior, prior_sigma = 9.0, 0.3, 9.6, 0.4
    precision = 1 / edr_sigma ** 2 + 1 / prior_sigma ** 2
    mean, std = (edr / edr_sigma ** 2 + prior / prior_sigma ** 2) / precision, precision ** -0.5
    unknowns = [fit.Unknown("vehicles[1].speed", 0.0, 30.0, prior=(prior, prior_sigma))]
    evidence = [fit.Evidence("vehicles[1].speed", edr, edr_sigma)]
    for chains in (2, 1):
        ess, rhat, worst, diverged = [], [], 0.0, 0
        for seed in range(seeds):
            post = fit.reconstruct(case, unknowns, evidence, posterior=draws, chains=chains, seed=seed).posterior
            s = post.summary["vehicles[1].speed"]
            ess.append(s["ess"])
            rhat.append(s["rhat"])
            diverged += post.divergences > 0
            worst = max(worst, abs(s["mean"] - mean) / (std / math.sqrt(s["ess"])),
                        abs(s["std"] - std) / (std / math.sqrt(2 * s["ess"])),
                        abs(s["q50"] - mean) / (1.2533 * std / math.sqrt(s["ess"])))
        print(f"\none unknown (closed-form Gaussian), {seeds} seeds x {chains} chain(s) x {draws} draws: ESS at least "
              f"{min(ess):.0f} (5% quantile {np.percentile(ess, 5):.0f}), R-hat at most "
              f"{'undefined' if chains < 2 else f'{max(rhat):.4f}'}, seeds diverged {diverged}, largest error "
              f"{worst:.2f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--targets", type=float, nargs="+", default=[0.8, 0.9])
    ap.add_argument("--one-draws", type=int, default=500, help="draws per chain of the one-unknown problem")
    args = ap.parse_args(argv)
    print(f"posterior_paths.py --seeds {args.seeds} --draws {args.draws} --targets "
          f"{' '.join(map(str, args.targets))} --one-draws {args.one_draws}: {jax.devices()[0].device_kind}, "
          f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC", flush=True)
    for restitution in (0.0, 0.3):
        for target in args.targets:
            paths(restitution, target, args.seeds, args.draws)
            sys.stdout.flush()
    one_unknown_paths(args.seeds, args.one_draws)


if __name__ == "__main__":
    main()
