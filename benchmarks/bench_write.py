"""Time to write a kept sweep to .csv, .npz and .parquet (``ks_jax.sweeps.write_results``). Not a test.

    .venv/bin/python benchmarks/bench_write.py [--n 1000] [--repeats 3] [--dir /tmp]

Solves an n x n grid of the seed case (default outputs), then writes it to each format in turn,
--repeats rounds, and prints every time and each file's size. A .csv is written twice: by pyarrow's CSV
writer (what ``ResultWriter`` uses where pyarrow is installed) and by ks-jax's own formatting (what it uses
without pyarrow, byte for byte the same file; here ``ks_jax.sweeps.files._arrow_csv`` is made to return None),
which is mostly Python's float formatting; the other two write the arrays as they are (.parquet needs pyarrow).
"""

import argparse
import datetime
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import ks_jax
import ks_jax.sweeps.files as files_module
from ks_jax.sweeps import write_results

CASE = Path(ks_jax.__file__).parent / "cases" / "seed_000_saturn_pontiac.json"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000, help="grid side (points = n^2)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--dir", default="/tmp", help="where the files are written (and deleted)")
    args = ap.parse_args()
    over = {"vehicles[1].speed": np.linspace(4.47, 26.8, args.n), "contact.restitution": np.linspace(0, 0.3, args.n)}
    result = ks_jax.sweep(ks_jax.load_case(CASE), over, progress=False)
    times, sizes = {}, {}
    for _ in range(args.repeats):
        for kind in (".csv (pyarrow)", ".csv (no pyarrow)", ".npz", ".parquet"):
            out = Path(args.dir) / f"bench_write{kind.split()[0]}"
            arrow_csv = files_module._arrow_csv
            if kind == ".csv (no pyarrow)":
                files_module._arrow_csv = lambda: None
            try:
                t = time.perf_counter()
                write_results(result, out)
                times.setdefault(kind, []).append(time.perf_counter() - t)
            finally:
                files_module._arrow_csv = arrow_csv
            sizes[kind] = out.stat().st_size
            out.unlink()
    print(f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {result.points:.3g} points, "
          f"{len(result.output_paths)} outputs + status; seconds to write, round by round:")
    for suffix, ts in times.items():
        print(f"  {suffix:18} {', '.join(f'{x:.2f}' for x in ts)}  ({sizes[suffix] / 1e6:.0f} MB)")


if __name__ == "__main__":
    main()
