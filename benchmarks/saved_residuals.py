"""How many values the reverse pass keeps for ``exchange.impulse_stage``: JAX's
``print_saved_residuals`` of the vmapped stage (its float outputs, differentiated in the inputs and the
sines/cosines of ``prepare``), on rows of bench_kernel.py's random batch. Not a test.

    .venv/bin/python benchmarks/saved_residuals.py [--rows 64] [--top 20]

Prints the count of saved residuals and where the most come from (source line). Module attributes that
select a variant (benchmarks/RESULTS.md) can be set first: ``--set ks_jax.exchange._HAND=1``.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import re
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent))
import ab_gradient  # noqa: E402
import bench_kernel as bk  # noqa: E402
from jax.ad_checkpoint import print_saved_residuals  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=64)
    ap.add_argument("--top", type=int, default=20)
    ap.add_argument("--set", action="append", default=[], metavar="MODULE.ATTR=VALUE")
    args = ap.parse_args()
    for spec in args.set:
        ab_gradient.set_attribute(spec)
    ex = sys.modules["ks_jax.exchange"]
    _, last = bk.random_batch(args.rows)
    rows = tuple(jax.tree_util.tree_map(lambda x: jax.numpy.moveaxis(x, -1, 0), t) for t in last)
    status, trig = jax.vmap(ex.prepare)(*rows)

    def floats(rows, trig):
        stage = jax.vmap(lambda *a: ex.impulse_stage(*a[:5], 0.0, a[5], a[6]))(*rows, status, trig)
        return stage._replace(sliding=None, approaching=None)

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        print_saved_residuals(floats, rows, trig)
    lines = out.getvalue().splitlines()
    sources = collections.Counter(re.sub(r"^\S+\s+", "", line) for line in lines)
    print(f"{len(lines)} saved residuals per row ({args.rows} rows; settings: {' '.join(args.set) or 'none'})")
    for source, count in sources.most_common(args.top):
        print(f"  {count:4d}  {source}")


if __name__ == "__main__":
    main()
