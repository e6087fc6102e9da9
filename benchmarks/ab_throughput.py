"""Forward throughput of this checkout against another, side by side. Not a test.

    .venv/bin/python benchmarks/ab_throughput.py --before DIR [--rounds 5] [--rows 1048576] [--calls 5]

DIR is a clean clone of another commit whose package has the same public names (``ks_jax.exchange``,
``ks_jax.exchange_batch``, ``ks_jax.Vehicle``, ``State``, ``Contact``), e.g.

    git clone -q . /tmp/before && git -C /tmp/before checkout -q COMMIT

Measures exchanges/s of ``jax.jit(jax.vmap(ks_jax.exchange))`` and of ``ks_jax.exchange_batch``, float64,
--rows rows, batch-first, every result computed, on the same random inputs (bench_kernel.py's rows around
the seed case, made once and saved to a temporary .npz). Each measurement is a fresh process of one
checkout: it puts the checkout first on ``sys.path`` (and stops unless ``ks_jax`` was imported from it: an
editable install of the other checkout does not take precedence), loads the inputs, calls each function
twice (compile, then a warm-up), then times --calls calls of each, alternating the two, and reports the
median of each. Processes of the two checkouts alternate, --rounds rounds, the order reversed every
other round (before, after; after, before; ...). Prints every round, the median over rounds of each
side, and after / before: the median over rounds of the ratio of the two sides' rates within a round.
It also checks that both sides computed the same results (sums of a few outputs over the valid rows).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CHECKOUT = HERE.parent
KINDS = (("vehicle1", "Vehicle"), ("state1", "State"), ("vehicle2", "Vehicle"), ("state2", "State"),
         ("contact", "Contact"))


def make_inputs(path: Path, rows: int) -> None:
    """bench_kernel.py's random rows, as plain arrays named ``vehicle1.mass``, ...: the same file for both
    sides (run in a process of its own, with this checkout)."""
    import numpy as np

    sys.path.insert(0, str(HERE))
    import bench_kernel

    nps, _ = bench_kernel.random_batch(rows)
    arrays = {f"{name}.{field}": np.asarray(x) for (name, _), d in zip(KINDS, nps) for field, x in d.items()}
    np.savez(path, **arrays)


def child(checkout: Path, inputs: Path, calls: int) -> None:
    """One measurement with ``checkout``'s ks_jax; prints one JSON line."""
    sys.path.insert(0, str(checkout))
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import ks_jax

    where = Path(ks_jax.__file__).resolve()
    if not where.is_relative_to(checkout):
        raise SystemExit(f"ks_jax was imported from {where}, not from {checkout}")
    data = np.load(inputs)
    args = tuple(getattr(ks_jax, kind)(**{f: jnp.asarray(data[f"{name}.{f}"]) for f in getattr(ks_jax, kind)._fields})
                 for name, kind in KINDS)
    args = jax.block_until_ready(args)
    rows = int(args[0].mass.shape[0])
    vmapped = jax.jit(jax.vmap(ks_jax.exchange))
    fns = {"jit(vmap(exchange))": lambda: jax.block_until_ready(vmapped(*args)),
           "exchange_batch": lambda: ks_jax.exchange_batch(*args)}
    first = {}
    for name, fn in fns.items():
        t = time.perf_counter()
        fn()
        first[name] = time.perf_counter() - t
        fn()  # warm-up
    times = {name: [] for name in fns}
    for _ in range(calls):
        for name, fn in fns.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    out = ks_jax.exchange_batch(*args)
    ok = np.asarray(out.contact.status) == 0
    sums = [float(np.sum(np.asarray(x)[ok])) for x in (out.contact.impulse_magnitude, out.contact.energy_loss,
                                                      out.vehicles[0].delta_v_magnitude, out.vehicles[1].pdof)]
    print(json.dumps({"ks_jax": str(where.parent), "rate": {k: rows / statistics.median(v) for k, v in times.items()},
                      "first": first, "valid": int(ok.sum()), "sums": sums}))


def measure(checkout: Path, inputs: Path, calls: int) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([sys.executable, __file__, "--child", str(checkout), "--inputs", str(inputs),
                           "--calls", str(calls)], env=env, capture_output=True, text=True, check=False)
    if done.returncode:
        raise SystemExit(f"{checkout}: the measurement failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="a clean clone of the other commit")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--calls", type=int, default=5, help="timed calls of each function per process (median)")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--inputs", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--make-inputs", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.make_inputs:
        return make_inputs(args.make_inputs, args.rows)
    if args.child:
        return child(args.child.resolve(), args.inputs, args.calls)
    if args.before is None:
        ap.error("--before DIR is required")
    sides = {"before": args.before.resolve(), "after": CHECKOUT}
    print(f"forward throughput, this checkout against another: {args.rows} rows, float64, batch-first, "
          f"{args.rounds} rounds, median of {args.calls} calls per process; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average {os.getloadavg()[0]:.2f}")
    for side, path in sides.items():
        print(f"  {side:6} {path}")
    with tempfile.TemporaryDirectory() as tmp:
        inputs = Path(tmp) / "inputs.npz"
        subprocess.run([sys.executable, __file__, "--make-inputs", str(inputs), "--rows", str(args.rows)], check=True)
        results = {side: [] for side in sides}
        for r in range(args.rounds):
            order = list(sides) if r % 2 == 0 else list(reversed(sides))
            for side in order:
                results[side].append(measure(sides[side], inputs, args.calls))
            line = "; ".join(f"{side} " + ", ".join(f"{k} {v:.4g}/s" for k, v in results[side][-1]["rate"].items())
                             for side in order)
            print(f"round {r + 1}: {line}", flush=True)
    names = list(results["after"][0]["rate"])
    print("\nexchanges/s, medians over rounds:")
    for name in names:
        med = {side: statistics.median(x["rate"][name] for x in results[side]) for side in sides}
        within = statistics.median(a["rate"][name] / b["rate"][name]
                                   for a, b in zip(results["after"], results["before"]))
        first = {side: statistics.median(x["first"][name] for x in results[side]) for side in sides}
        print(f"  {name:20} before {med['before']:.4g}/s, after {med['after']:.4g}/s: after/before {within:.3f} "
              f"(first call {first['before']:.2f} s before, {first['after']:.2f} s after)")
    b, a = results["before"][0], results["after"][0]
    worst = max(abs(x - y) / max(abs(y), 1e-300) for x, y in zip(a["sums"], b["sums"]))
    print(f"same results: valid rows {a['valid']} after, {b['valid']} before; sums of four outputs differ by at most "
          f"{worst:.1e} (relative); ks_jax from {a['ks_jax']} and {b['ks_jax']}")


if __name__ == "__main__":
    main()
