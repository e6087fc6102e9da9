"""The first call of ``fit.reconstruct_batch`` in a fresh process, on a plan's path: its seconds, and the programs
it traced and compiled (``jax.monitoring``'s compile events). Not a test.

    .venv/bin/python benchmarks/fit_first_call.py [--plan accelerator] [--cases 200]

``bench_fit.py``'s random sliding side impacts x 8 starts, the default settings. Run once per plan, each in its own
process (a second call in one process would find the first call's programs): on a CPU the accelerator's plan
shows how many programs its first call compiles (on a GPU, where compiling takes longer, that is most of it).
"""

from __future__ import annotations

import argparse
import collections
import datetime
import sys
import time
from pathlib import Path

import jax
import jax.monitoring

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_fit

import fit

EVENTS = {"/jax/core/compile/backend_compile_duration": "XLA compiles",
          "/jax/core/compile/jaxpr_trace_duration": "traces"}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plan", default=None, help="cpu or accelerator (default: the devices')")
    parser.add_argument("--cases", type=int, default=200)
    args = parser.parse_args(argv)
    cases, _, evidence, unknowns, _ = bench_fit.sliding_cases(args.cases, 0)
    count, seconds = collections.Counter(), collections.Counter()

    def listen(event, duration, **_):
        if event in EVENTS:
            count[event] += 1
            seconds[event] += duration

    jax.monitoring.register_event_duration_secs_listener(listen)
    start = time.perf_counter()
    fit.reconstruct_batch(cases, unknowns, evidence, starts=8, seed=2, smoothing=bench_fit.SMOOTHING, plan=args.plan)
    wall = time.perf_counter() - start
    print(f"fit_first_call.py --plan {args.plan} --cases {args.cases}: {jax.devices()[0].device_kind}, "
          f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC")
    print(f"  first call {wall:.1f} s; " + ", ".join(f"{EVENTS[e]} {count[e]} ({seconds[e]:.1f} s)" for e in EVENTS))


if __name__ == "__main__":
    main()
