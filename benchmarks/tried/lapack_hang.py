"""Two batched LAPACK calls at once on a CPU: does the program return? Not a test.

    .venv/bin/python benchmarks/tried/lapack_hang.py [--rows 1048576] [--timeout 60] [--tries 3]

Why benchmarks/naive_ks.py inverts both inertias in one call, and why tests/test_batch.py checks that the
library's batched programs call no library routine. Each try runs, in a fresh process with a time limit,
one jitted program holding two batched ``jnp.linalg.inv`` of (rows, 3, 3) float64 matrices: once
independent of each other (XLA may run them at the same time), once the second waiting for the first
(its input depends on the first's output). Prints, per variant, how many tries returned, and the time
of those that did.
"""

from __future__ import annotations

import argparse
import subprocess
import sys

CHILD = """
import sys, time
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
n, chained = int(sys.argv[1]), sys.argv[2] == "chained"
rng = np.random.default_rng(0)
a, b = (jnp.asarray(np.eye(3) + 0.1 * rng.standard_normal((n, 3, 3))) for _ in range(2))

def f(a, b):
    first = jnp.linalg.inv(a)
    if chained:
        b = b + 0.0 * first[..., :1, :1]
    return first, jnp.linalg.inv(b)

run = jax.jit(f).lower(a, b).compile()
t = time.perf_counter()
jax.block_until_ready(run(a, b))
print(time.perf_counter() - t)
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--tries", type=int, default=3)
    args = ap.parse_args()
    import jax

    print(f"two batched jnp.linalg.inv of ({args.rows}, 3, 3) in one program, jax {jax.__version__}, "
          f"{args.tries} tries of {args.timeout:.0f} s each")
    for variant in ("independent", "chained"):
        times = []
        for _ in range(args.tries):
            try:
                done = subprocess.run([sys.executable, "-c", CHILD, str(args.rows), variant], capture_output=True,
                                      text=True, timeout=args.timeout)
                times.append(float(done.stdout.split()[-1]))
            except subprocess.TimeoutExpired:
                pass
        shown = ", ".join(f"{t:.3f} s" for t in times)
        print(f"  {variant:11s} returned {len(times)} of {args.tries}" + (f" ({shown})" if times else ""))


if __name__ == "__main__":
    main()
