"""The first call of a reconstruction (compile and run) in a fresh process. Not a test.

    .venv/bin/python benchmarks/bench_fit_first_call.py [--monte-carlo N]

Fits the automatic-contact T-bone shipped in the package (``auto_tbone.json``: the pickup's speed and the
friction unknown) to four results of its own solution (both delta-V magnitudes, the sedan's speed after
and PDOF) and prints the time of ``fit.reconstruct`` (compiling included: each run is a fresh process, with
no persistent compile cache) and the estimate. For an A/B, run it in alternating processes with each
version on ``PYTHONPATH``. The evidence is the case's own panel (30 mph, friction 0.5), rounded: the speed
comes back at 30.00 mph; from a friction of about 0.31 up the contact sticks and every friction gives the same
results, so the evidence bounds the friction from below only (the fit says so), and the friction it stops at
is not a measurement.
"""

from __future__ import annotations

import argparse
import datetime
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import fit  # noqa: E402
import ks_jax  # noqa: E402
from ks_jax.units import MPH  # noqa: E402

EVIDENCE = [{"quantity": "vehicles[0].delta_v_magnitude", "value": "11.38 mph", "sigma": "0.5 mph"},
            {"quantity": "vehicles[1].delta_v_magnitude", "value": "7.82 mph", "sigma": "0.5 mph"},
            {"quantity": "vehicles[0].speed_after", "value": "15.92 mph", "sigma": "1 mph"},
            {"quantity": "vehicles[0].pdof", "value": 72.8, "sigma": 5}]
UNKNOWNS = {"vehicles[1].speed": {"bounds": ["10 mph", "60 mph"]}, "contact.friction": {"bounds": [0.05, 1.0]}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--monte-carlo", type=int, default=0)
    args = ap.parse_args()
    case = ks_jax.load_case(Path(ks_jax.__file__).parent / "cases" / "auto_tbone.json")
    t = time.perf_counter()
    r = fit.reconstruct(case, UNKNOWNS, EVIDENCE, monte_carlo=args.monte_carlo)
    t = time.perf_counter() - t
    print(f"{datetime.datetime.now().astimezone().isoformat(timespec='seconds')} jax {jax.__version__} "
          f"{jax.default_backend()}: fit.reconstruct (first call) {t:.2f} s; speed "
          f"{r.estimate['vehicles[1].speed'] / MPH:.3f} mph, friction {r.estimate['contact.friction']:.4f}, "
          f"converged {r.converged}, {r.iterations} iterations")


if __name__ == "__main__":
    main()
