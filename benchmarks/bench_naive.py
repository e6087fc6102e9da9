"""The naive baseline: ``jax.jit(jax.vmap)`` of the exchange written with batched 3x3 LAPACK solves,
measured beside NumPy, streaming and the library. Not a test.

    .venv/bin/python benchmarks/bench_naive.py [--rows 1048576] [--repeats 5]

The baseline (benchmarks/naive_ks.py: ``jnp.linalg.inv`` and ``jnp.linalg.solve`` per row, batched by
``jax.jit(jax.vmap)``) is timed in rounds beside the same references as bench_kernel.py: the NumPy
implementation (numpy_ks.py), the two streaming references over the bytes of the library's inputs and
results (into new arrays, and in place), and the library's own ``jax.jit(jax.vmap(ks_jax.exchange))``,
batch-first. Then gradient / forward of bench_kernel.py's two batched losses through the baseline and, in
the same rounds, through ``jax.vmap(ks_jax.exchange)``. It prints the figures, and last a one-line
summary (bench_kernel.py runs this script in a process of its own and prints that line).

The baseline inverts both vehicles' inertias in one ``jnp.linalg.inv`` call (and takes both determinants
in one ``jnp.linalg.det``): XLA runs independent calls at the same time, and a program holding two
independent batched ``jnp.linalg.inv`` of 8192 or more 3x3 matrices did not return, with all its threads
asleep, on a 2-core machine with JAX 0.10.2. The library itself makes no LAPACK call (benchmarks/checks.py
checks it).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_kernel as bk
import naive_ks
import numpy_ks

import ks_jax


def naive_losses():
    """bench_kernel.py's two losses on the baseline's results, summed over the valid rows."""
    def dv(out):
        c, v = out
        return v[0]["delta_v_magnitude"] + v[1]["delta_v_magnitude"]

    def residuals(out):
        c, v = out
        total = 0.0
        for k, r in enumerate(v):
            total = total + (r["delta_v_magnitude"] - 5.0) ** 2 + (r["speed_after"] - 8.0) ** 2 \
                + (1 - jnp.cos(jnp.radians(r["course_after"] - 10.0))) \
                + (1 - jnp.cos(jnp.radians(r["pdof"] - 30.0 * k))) + (r["yaw_rate_after"] - 0.1) ** 2
        return total

    def batched(row_loss):
        def loss(args):
            out = jax.vmap(naive_ks.exchange)(*args)
            return jnp.sum(jnp.where(out[0]["status"] == 0, row_loss(out), 0.0))
        return loss

    return {"delta-V": batched(dv), "residuals": batched(residuals)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    n, reps = args.rows, args.repeats
    print(f"naive baseline, {n} rows, {reps} rounds, jax {jax.__version__}, {bk.cpu_model()}")

    nps, first = bk.random_batch(n)
    dicts = jax.block_until_ready(jax.tree_util.tree_map(jnp.asarray, nps))
    naive = jax.jit(jax.vmap(naive_ks.exchange))
    kernel = jax.jit(jax.vmap(ks_jax.exchange))
    first_naive = bk.first_call(lambda: jax.block_until_ready(naive(*dicts)))
    out = jax.block_until_ready(kernel(*first))

    # the naive results against NumPy's (the invalid rows, NaN in both, left out)
    ref_c, ref_v = numpy_ks.exchange(*jax.tree_util.tree_map(lambda x: x[:4096], nps))
    got_c, got_v = jax.tree_util.tree_map(lambda x: np.asarray(x[:4096]), naive(*dicts))
    valid = ref_c["status"] == 0
    agree = max(float(np.max(np.abs(got_c[k] - ref_c[k])[valid] / np.abs(ref_c[k])[valid]))
                for k in ("impulse_magnitude", "energy_loss"))
    same_status = bool(np.array_equal(got_c["status"], ref_c["status"]))

    # the streaming references of bench_kernel.py, over the library's bytes in and out
    stream, stream_in_place, _ = bk.streaming_references(first, out)
    fns = {
        "naive": lambda: jax.block_until_ready(naive(*dicts)),
        "kernel": lambda: jax.block_until_ready(kernel(*first)),
        "numpy": lambda: numpy_ks.exchange(*nps),
        "stream": stream,
        "stream_in_place": stream_in_place,
    }
    for fn in fns.values():
        fn()
    times = bk.rounds(fns, reps)
    rate = {k: n / statistics.median(v) for k, v in times.items()}
    q = lambda a, b: bk.ratio(times, a, b)  # noqa: E731

    # gradient / forward of the two losses through the baseline, and through ks_jax.exchange (as
    # bench_kernel.py takes it: jax.vmap(exchange), batch-first, every input) in the same rounds
    gfns, firsts = {}, {}
    for name, loss in naive_losses().items():
        lib_loss = bk.batched_loss(bk.LOSSES[name], "vmap(exchange)")
        for who, f, a in (("naive", loss, (dicts,)),
                          ("ks_jax", lambda args, lib_loss=lib_loss: lib_loss(*args), (tuple(first),))):
            fwd, grad = jax.jit(f), jax.jit(jax.value_and_grad(f))
            bk.first_call(lambda: jax.block_until_ready(fwd(*a)))
            first_grad = bk.first_call(lambda: jax.block_until_ready(grad(*a)))
            if who == "naive":
                firsts[name] = first_grad
            gfns[(who, name, "forward")] = lambda fwd=fwd, a=a: jax.block_until_ready(fwd(*a))
            gfns[(who, name, "gradient")] = lambda grad=grad, a=a: jax.block_until_ready(grad(*a))
    gt = bk.rounds(gfns, reps)

    w = 44
    print(f"{'':{w}} {'exchanges/s':>14}")
    for key, label in (("naive", "naive jit(vmap), batched 3x3 LAPACK"),
                       ("kernel", "ks_jax jit(vmap(exchange)), batch-first"),
                       ("numpy", "NumPy vectorized (numpy_ks.py)"),
                       ("stream", "stream x*1.0+0 into new arrays"),
                       ("stream_in_place", "same, in place (donated)")):
        print(f"{label:{w}} {rate[key]:14.4g}")
    print(f"naive: /NumPy {q('naive', 'numpy'):.2f}, /streaming {q('naive', 'stream'):.3f}, "
          f"/streaming in place {q('naive', 'stream_in_place'):.3f}; first call {first_naive:.2f} s; "
          f"agrees with NumPy to {agree:.1e}, statuses equal: {same_status}")
    print(f"ks_jax jit(vmap(exchange)): /NumPy {q('kernel', 'numpy'):.2f}, /streaming {q('kernel', 'stream'):.3f}, "
          f"/streaming in place {q('kernel', 'stream_in_place'):.3f}, /naive {q('kernel', 'naive'):.2f}")
    grads, lib_grads, faster_grads, lib_ns = {}, {}, {}, {}
    for name in firsts:
        tf, tg = (statistics.median(gt[("naive", name, k)]) for k in ("forward", "gradient"))
        grads[name] = bk.ratio(gt, ("naive", name, "forward"), ("naive", name, "gradient"))
        lib = bk.ratio(gt, ("ks_jax", name, "forward"), ("ks_jax", name, "gradient"))
        faster = bk.ratio(gt, ("ks_jax", name, "gradient"), ("naive", name, "gradient"))
        lib_grads[name], faster_grads[name] = lib, faster
        lf, lg = (statistics.median(gt[("ks_jax", name, k)]) for k in ("forward", "gradient"))
        lib_ns[name] = f"{lg * 1e9 / n:.0f}/{lf * 1e9 / n:.0f}"
        print(f"naive gradient/forward, {name}: {grads[name]:.2f} (gradient {n / tg:.4g}/s, forward "
              f"{n / tf:.4g}/s; first call {firsts[name]:.2f} s); through ks_jax.exchange {lib:.2f} (gradient "
              f"{n / lg:.4g}/s, forward {n / lf:.4g}/s), its gradient {faster:.2f}x the naive gradient's rate")
    print(f"naive jit(vmap): {q('naive', 'numpy'):.2f}x NumPy, {q('naive', 'stream'):.2f} of streaming into new "
          f"arrays, {q('naive', 'stream_in_place'):.2f} in place; ks_jax jit(vmap(exchange)) "
          f"{q('kernel', 'naive'):.2f}x it; naive gradient/forward {grads['delta-V']:.2f} (delta-V), "
          f"{grads['residuals']:.2f} (residuals); through ks_jax.exchange {lib_grads['delta-V']:.2f} and "
          f"{lib_grads['residuals']:.2f} (medians, gradient/forward ns per row: {lib_ns['delta-V']} and "
          f"{lib_ns['residuals']}), its gradients {faster_grads['delta-V']:.2f}x and {faster_grads['residuals']:.2f}x "
          "the naive ones' rate")


if __name__ == "__main__":
    main()
