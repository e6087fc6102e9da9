"""Where the first call of a batched program, a solve or a fit spends its time: tracing (JAX, in Python),
lowering and XLA's compile, as ``jax.monitoring`` reports them, and the call's wall time. Not a test.

    .venv/bin/python benchmarks/ab_first_call.py [--rows N] [--only NAME ...]

Each item runs in this one process, in order, with no persistent compile cache: later items find the
programs earlier ones compiled (``ks_jax.solve``'s and ``sweep``'s programs are jitted once per process),
so compare an item only with the same item of another run of the same list. For an A/B, run the script
in alternating processes with each version of the library on ``PYTHONPATH`` (a clean clone of the other
commit) and compare the items side by side.

Items: ``forward`` (``jax.jit(jax.vmap(exchange))``, batch-first, over ``--rows`` rows, default 2^16:
four chunks), ``grad`` (``jax.value_and_grad`` of bench_kernel.py's delta-V loss through
``jax.vmap(exchange)``), ``summed`` (the same loss built by ``ks_jax.sum_over_rows``), ``solve-auto``
(``ks_jax.solve`` of the shipped automatic-contact case), ``fit`` (``fit.reconstruct`` of
``fit_seed_001.json``), ``fit-auto`` (bench_fit_first_call.py's automatic-contact fit).
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_fit_first_call as bf  # noqa: E402
import bench_kernel as bk  # noqa: E402
import fit  # noqa: E402
import ks_jax  # noqa: E402

EVENTS = {"/jax/core/compile/jaxpr_trace_duration": "trace", "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
          "/jax/core/compile/backend_compile_duration": "compile"}
_totals = {}


def _listen(event, duration, **_):
    if event in EVENTS:
        _totals[EVENTS[event]] = _totals.get(EVENTS[event], 0.0) + duration


def items(rows):
    cases = Path(ks_jax.__file__).parent / "cases"
    first = bk.batch_first(bk.random_batch(rows)[1])
    loss = bk.batched_loss(bk.delta_v, 0, chunked=True)
    summed = bk.batched_loss(bk.delta_v, 0, summed=True)
    return {
        "forward": lambda: jax.jit(lambda a: loss(a, None))(first),
        "grad": lambda: jax.jit(jax.value_and_grad(lambda a: loss(a, None)))(first),
        "summed": lambda: jax.jit(jax.value_and_grad(lambda a: summed(a, None)))(first),
        "solve-auto": lambda: ks_jax.solve(ks_jax.load_case(cases / "auto_seed_000.json")),
        "fit": lambda: fit.reconstruct(ks_jax.load_case(cases / "fit_seed_001.json")),
        "fit-auto": lambda: fit.reconstruct(ks_jax.load_case(cases / "auto_tbone.json"), bf.UNKNOWNS, bf.EVIDENCE),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 16)
    ap.add_argument("--only", nargs="+", metavar="NAME")
    args = ap.parse_args()
    jax.monitoring.register_event_duration_secs_listener(_listen)
    todo = items(args.rows)
    names = args.only or list(todo)
    print(f"{datetime.datetime.now().astimezone().isoformat(timespec='seconds')} jax {jax.__version__} "
          f"{jax.default_backend()}, ks_jax from {Path(ks_jax.__file__).parent}")
    for name in names:
        _totals.clear()
        start = time.perf_counter()
        jax.block_until_ready(todo[name]())
        wall = time.perf_counter() - start
        print(f"{name:10s} first call {wall:6.2f} s: trace {_totals.get('trace', 0):5.2f}, lower "
              f"{_totals.get('lower', 0):5.2f}, compile {_totals.get('compile', 0):5.2f} s", flush=True)


if __name__ == "__main__":
    main()
