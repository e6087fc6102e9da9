"""Memory of ``jax.jit(jax.vmap(ks_jax.exchange))`` over one batch, and of ``jax.value_and_grad`` of a
batched loss: the chunked programs (``exchange``'s vmap rules) against the whole-batch programs
(``exchange_with_status`` after ``input_status``), and the gradient of the same losses built by
``ks_jax.sum_over_rows`` ("summed"). Not a test.

    .venv/bin/python benchmarks/bench_vmap_memory.py [--rows 1048576]

For each program, in a fresh process: XLA's temporary and output bytes (``compiled.memory_analysis()``)
and how much one call raised the process's peak resident memory (VmHWM,
``bench_sweep_memory.peak_rss_mib``). The losses are those of bench_kernel.py (the sum of the
delta-V magnitudes; the squared residuals), gradients over every input.
"""

import argparse
import datetime
import subprocess
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_kernel import batch_first, batched_loss, delta_v, random_batch, residuals  # noqa: E402
from bench_sweep_memory import peak_rss_mib  # noqa: E402

from ks_jax.exchange import exchange, exchange_with_status, input_status  # noqa: E402

MIB = 2.0**20


def measure(variant, n):
    _, last = random_batch(n)
    first = batch_first(last)
    del last
    chunked = variant.startswith("chunked")
    if " " in variant:  # "chunked delta-V", "whole residuals": value_and_grad of that loss
        loss = batched_loss({"delta-V": delta_v, "residuals": residuals}[variant.split()[1]], 0, chunked,
                            summed=variant.startswith("summed"))
        status = jax.jit(jax.vmap(input_status))(*first)
        jitted, args = jax.jit(jax.value_and_grad(loss)), (tuple(first), status)
    else:
        fn = exchange if chunked else (lambda *a: exchange_with_status(*a, 0.0, input_status(*a)))
        jitted, args = jax.jit(jax.vmap(fn)), tuple(first)
    mem = jitted.lower(*args).compile().memory_analysis()
    before = peak_rss_mib()
    jax.block_until_ready(jitted(*args))
    after = peak_rss_mib()
    print(f"{variant:18} XLA temporaries {mem.temp_size_in_bytes / MIB:7.1f} MiB, results "
          f"{mem.output_size_in_bytes / MIB:7.1f} MiB; peak RSS {before:7.0f} -> {after:7.0f} MiB "
          f"(+{after - before:.0f})", flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--variant", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.variant:
        measure(args.variant, args.rows)
        return
    print(f"jax.jit(jax.vmap(exchange)) and gradient memory, {args.rows} rows, batch-first, float64; "
          f"{datetime.datetime.now().astimezone().isoformat(timespec='seconds')}; jax {jax.__version__}")
    variants = [f"{kind} {loss}".strip() for loss in ("", "delta-V", "residuals") for kind in ("chunked", "whole")]
    variants += ["summed delta-V", "summed residuals"]
    for variant in variants:  # each in its own process: the peak is a high-water mark
        subprocess.run([sys.executable, __file__, "--rows", str(args.rows), "--variant", variant], check=True)


if __name__ == "__main__":
    main()
