"""The default device's figures, one script: kernel, streaming, exchange_batch, a sweep, gradient / forward, fits.
Not a test.

    .venv/bin/python benchmarks/bench_device.py [--rows N] [--sweep N] [--fits N] [--many N] [--profile DIR]

Prints the device, the date and the command, then, each the median of --repeats calls after a first
(compiling) call:

- the kernel: ``jax.jit(jax.vmap(ks_jax.exchange))`` over --rows random rows around the seed case (inputs
  and results on the device), float64 and float32, batch-first and batch-last (``in_axes=-1``);
- streaming: a jitted x * a + b over arrays as large as the kernel's inputs and results (each read and
  written once): the device's rate for the same bytes; the kernel's bytes (inputs read, results written
  once) over its time, as a fraction of that rate;
- ``ks_jax.exchange_batch`` over the same rows: from NumPy arrays into NumPy arrays, from device arrays
  into NumPy arrays, and from device arrays into device arrays (``to_host=False``);
- ``ks_jax.sweep`` of --sweep points (a square grid of two inputs) with ``keep=False``, and with the
  default outputs kept;
- gradient / forward of a batched loss (both delta-V magnitudes, rows not OK masked) built with
  ``ks_jax.sum_over_rows``;
- ``fit.reconstruct_batch`` of --fits random sliding side impacts x 8 starts (``bench_fit.py``'s cases), and the
  host's work of that call (its solver's calls replayed from a recording: ``bench_fit.host_seconds``); then a batch
  of --many reconstructions (the --fits cases repeated, each its own rows): reconstructions per second (with
  ``--blocks``, for each of those most rows a call of the solver holds on an accelerator, side by side); of each,
  the solver's work in a further call (``bench_fit.solver_work``: its rows x loop iterations against the rows' own);
- motion to rest: --motions two-vehicle motions (``bench_motion.py``'s random pairs, 3 s of motion at the default
  step, stopping once every vehicle rests) on the default device, the way its plan computes them (``backend.Plan``:
  blocks of 256 vehicles on the CPU's path, all at once on an accelerator's), in motions per second, and
  --cpu-motions of them on the host's CPU the CPU's way: the ratio of the two rates; then a case with later
  exchanges (``tbone_spin_out.json``: the watched motion after the first exchange, docs/model.md "Contact
  interactions") swept over --interaction points, on the default device and on the CPU: points per second.

Defaults: 2^22 rows, 10^8 sweep points, 1000 fits and 10^5 in a batch, 10^6 motions and 10^5 points of the
interaction on an accelerator; 2^16, 10^6, 100, none, 10^4 and 10^3 on a CPU; 10^4 motions and 10^3 points on the
CPU for the comparison.
--profile DIR: also writes the compiled programs of the kernel (float32 and float64) and, for the kernel,
``exchange_batch`` and the fits, a table of the device's kernels by time (``jax.profiler``) to DIR.
"""

from __future__ import annotations

import argparse
import datetime
import glob
import inspect
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_fit
import bench_motion
from bench_kernel import delta_v, random_batch, streaming_references

import fit
import ks_jax
from ks_jax.backend import plan_for
from ks_jax.batch.stages import BLOCK_ROWS, in_blocks
from ks_jax.model import collision
from ks_jax.model import motion_loop as ML

CASE = Path(ks_jax.__file__).resolve().parent / "cases" / "seed_000_saturn_pontiac.json"


def median_time(fn, repeats):
    """Median wall time of ``fn()`` (which blocks) over ``repeats`` calls, after one call that compiles."""
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def blocking(fn, *args, **kw):
    return lambda: jax.block_until_ready(fn(*args, **kw))


def kernel_table(fn, what, out_dir, top=12):
    """Run ``fn`` under ``jax.profiler`` and print the device's kernels by total time (name, launches, time):
    where the device's time goes, and how much of the wall time it is busy."""
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        with jax.profiler.trace(d):
            fn()
        wall = time.perf_counter() - t
        files = glob.glob(f"{d}/**/*.xplane.pb", recursive=True)
        if not files:
            print(f"  {what}: no profile written")
            return
        data = jax.profiler.ProfileData.from_file(files[0])
    kernels, busy = {}, 0.0
    for plane in data.planes:
        if not plane.name.startswith("/device:"):
            continue
        for line in plane.lines:
            if "stream" not in line.name.lower():
                continue
            for e in line.events:
                n, t_ns = kernels.get(e.name, (0, 0.0))
                kernels[e.name] = (n + 1, t_ns + e.duration_ns)
                busy += e.duration_ns
    lines = [f"## {what}: wall {wall * 1e3:.1f} ms (profiled), device streams busy {busy / 1e6:.1f} ms, "
             f"{sum(n for n, _ in kernels.values())} launches of {len(kernels)} kernels"]
    for name, (n, t_ns) in sorted(kernels.items(), key=lambda kv: -kv[1][1])[:top]:
        lines.append(f"  {t_ns / 1e6:9.3f} ms  {n:6d} x  {name[:110]}")
    text = "\n".join(lines)
    print(text, flush=True)
    if out_dir:
        with open(Path(out_dir) / "kernels.txt", "a") as f:
            f.write(text + "\n\n")


def as_dtype(tree, dtype):
    return jax.tree_util.tree_map(lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x, tree)


MOTION_SECONDS = 3.0


def _motion_program(device):
    """The jitted forward of two-vehicle motions to rest on ``device``, computed the way its plan says (blocks of
    ``BLOCK_ROWS`` vehicles on the CPU's path, as a case's pipeline runs them; all rows at once elsewhere)."""
    def one(mass, izz, h, chassis, wheels, mu, start):
        return ML.to_rest(mass, izz, h, chassis, wheels, mu, start, time_limit=MOTION_SECONDS).rest_position

    rows = jax.vmap(one)
    if plan_for(None, [device]).cpu:
        rows = in_blocks(rows, BLOCK_ROWS, (0,) * 7)
    return jax.jit(rows)


def _motion_rate(pairs, device, repeats):
    """(motions per second, first call's seconds) of ``pairs`` two-vehicle motions on ``device``."""
    data = jax.device_put(bench_motion.vehicles(2 * pairs), device)
    program = _motion_program(device)
    t = time.perf_counter()
    jax.block_until_ready(program(*data))
    first = time.perf_counter() - t
    return pairs / median_time(blocking(program, *data), repeats), first


def _interaction_rate(points, device, repeats):
    """(points per second, first call's seconds) of a sweep of ``tbone_spin_out.json`` over the pickup's speed
    (``points`` points, the watched motion after the first exchange in every one) on ``device``."""
    case = ks_jax.load_case(CASE.parent / "tbone_spin_out.json")
    over = {"vehicles[0].speed": np.linspace(10.0, 20.0, points)}

    def call():
        return ks_jax.sweep(case, over, outputs=["vehicles[0].rest_position[0]"], devices=[device], keep=False,
                            progress=False)

    t = time.perf_counter()
    call()
    first = time.perf_counter() - t
    return points / median_time(call, repeats), first


def motions_to_rest(args, row):
    """The motion section: motions to rest and a case with later exchanges, on the default device and the CPU."""
    dev, cpu = jax.devices()[0], jax.devices("cpu")[0]
    repeats = max(1, min(args.repeats, 3))
    here, first = _motion_rate(args.motions, dev, repeats)
    there, _ = (here, first) if dev == cpu and args.cpu_motions == args.motions else \
        _motion_rate(args.cpu_motions, cpu, repeats)
    row(f"motions to rest, {args.motions} two-vehicle, {MOTION_SECONDS:g} s, float64", f"{here:.3g} /s",
        f"first call {first:.1f} s; the CPU ({args.cpu_motions} motions): {there:.3g} /s, ratio {here / there:.2f}")
    here, first = _interaction_rate(args.interaction, dev, repeats)
    cpu_points = min(args.interaction, 10 ** 3)
    there, _ = (here, first) if dev == cpu and cpu_points == args.interaction else \
        _interaction_rate(cpu_points, cpu, repeats)
    row(f"sweep of tbone_spin_out.json (later exchanges), {args.interaction} points", f"{here:.3g} /s",
        f"first call {first:.1f} s; the CPU ({cpu_points} points): {there:.3g} /s, ratio {here / there:.2f}")


def many_fits(args, many, row):
    """``fit.reconstruct_batch`` of the batch ``many`` after a compiling call, for each of ``--blocks`` (the most rows a
    call of the solver holds on an accelerator, ``fit.rows.ROWS_PER_CALL_ELSEWHERE``; default the library's), side by
    side: fits per second, the host's work, the solver's work."""
    kept = fit.rows.ROWS_PER_CALL_ELSEWHERE
    cpu = plan_for(None).cpu  # the blocks are the accelerator's path's only
    try:
        for block in [int(b) for b in args.blocks.split(",")] if args.blocks and not cpu else [kept]:
            fit.rows.ROWS_PER_CALL_ELSEWHERE = block
            fit.reconstruct_batch(*many, starts=8, smoothing=bench_fit.SMOOTHING)

            def many_call():
                return fit.reconstruct_batch(*many, starts=8, seed=1, smoothing=bench_fit.SMOOTHING)

            walls = []
            with bench_fit.recording([]) as calls:
                for _ in range(args.repeats):
                    calls.clear()
                    t = time.perf_counter()
                    many_call()
                    walls.append(time.perf_counter() - t)
            wall = float(np.median(walls))
            host = bench_fit.host_seconds(calls, many_call, repeats=1)
            with bench_fit.solver_work() as work:
                many_call()
            where = "the CPU's path" if cpu else f"calls of at most {block} rows"
            row(f"reconstruct_batch, {len(many[0])} x 8 starts (the {args.fits} repeated), {where}",
                f"{len(many[0]) / wall:.3g} /s",
                f"{wall:.2f} s (median of {args.repeats}); host work {host:.2f} s ({1e3 * host / len(many[0]):.3f} ms "
                f"per fit); {bench_fit.work_note(work)}")
    finally:
        fit.rows.ROWS_PER_CALL_ELSEWHERE = kept


def main(argv=None):
    accel = jax.default_backend() != "cpu"
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 22 if accel else 1 << 16)
    ap.add_argument("--sweep", type=int, default=10 ** 8 if accel else 10 ** 6, help="sweep points")
    ap.add_argument("--fits", type=int, default=1000 if accel else 100, help="reconstructions (x 8 starts)")
    ap.add_argument("--many", type=int, default=10 ** 5 if accel else 0,
                    help="a batch of this many reconstructions, the --fits cases repeated (0: none)")
    ap.add_argument("--blocks", default="",
                    help="the batch of --many fits with calls of at most these many rows, comma-separated (e.g. "
                         "8000,16000,32000; default: the library's)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--profile", metavar="DIR", help="write compiled programs and kernel tables to DIR")
    ap.add_argument("--motions", type=int, default=10 ** 6 if accel else 10 ** 4,
                    help="two-vehicle motions to rest on the default device")
    ap.add_argument("--cpu-motions", type=int, default=10 ** 4, help="the same on the host's CPU, for the ratio")
    ap.add_argument("--interaction", type=int, default=10 ** 5 if accel else 10 ** 3,
                    help="sweep points of a case with later exchanges on the default device (10^3 on the CPU)")
    ap.add_argument("--only", default="kernel,batch,sweep,grad,fit,motion", help="sections to run, comma-separated")
    args = ap.parse_args(argv)
    only = set(args.only.split(","))
    dev = jax.devices()[0]
    stats = {}
    try:
        stats = dev.memory_stats() or {}
    except Exception:  # noqa: BLE001 (a backend without memory statistics)
        pass
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    print(f"device: {dev.device_kind} ({jax.default_backend()}, {jax.device_count()} device(s), "
          f"{stats.get('bytes_limit', 0) / 2**30:.0f} GiB for XLA), host {platform.machine()} {os.cpu_count()} cores, "
          f"jax {jax.__version__}")
    print(f"command: python {' '.join([Path(sys.argv[0]).as_posix(), *(argv or sys.argv[1:])])}\ndate: {date}",
          flush=True)
    if args.profile:
        Path(args.profile).mkdir(parents=True, exist_ok=True)
    table = []
    n = args.rows

    def row(what, value, note=""):
        table.append(f"| {what} | {value} | {note} |")
        print(table[-1], flush=True)

    nps, batch = random_batch(n)
    kernel_rate = {}
    if "kernel" in only or "batch" in only:
        for dtype in (jnp.float64, jnp.float32):
            name = np.dtype(dtype).name
            inputs = as_dtype(batch, dtype)
            fn = jax.jit(jax.vmap(ks_jax.exchange))
            outputs = jax.block_until_ready(fn(*inputs))
            stream, _, nb = streaming_references(inputs, outputs, dtype)
            t_stream = median_time(stream, args.repeats)
            t_kernel = median_time(blocking(fn, *inputs), args.repeats)
            kernel_rate[name] = n / t_kernel
            stream_rate = 2 * nb / t_stream
            row(f"streaming, {name} ({nb / n:.0f} bytes per row, read and written)", f"{stream_rate / 1e9:.0f} GB/s")
            row(f"jit(vmap(exchange)), {name}, batch-first", f"{n / t_kernel:.3g} /s",
                f"{nb / t_kernel / 1e9:.0f} GB/s = {nb / t_kernel / stream_rate:.2f} of streaming")
            last = jax.tree_util.tree_map(lambda x: jnp.moveaxis(x, 0, -1), inputs)
            fn_last = jax.jit(jax.vmap(collision.exchange, in_axes=-1, out_axes=-1))
            t_last = median_time(blocking(fn_last, *last), args.repeats)
            row(f"jit(vmap(exchange)), {name}, batch-last", f"{n / t_last:.3g} /s",
                f"{nb / t_last / 1e9:.0f} GB/s = {nb / t_last / stream_rate:.2f} of streaming")
            if args.profile:
                Path(args.profile, f"kernel_{name}.hlo.txt").write_text(fn.lower(*inputs).compile().as_text())
                kernel_table(blocking(fn, *inputs), f"kernel {name}, {n} rows", args.profile)
            del inputs, outputs, last
    if "batch" in only:
        host = jax.tree_util.tree_map(np.asarray, batch)
        base = kernel_rate.get("float64")
        t = median_time(lambda: ks_jax.exchange_batch(*host), args.repeats)
        row("exchange_batch, NumPy in, NumPy out", f"{n / t:.3g} /s",
            f"{n / t / base:.2f} of the kernel" if base else "")
        t = median_time(lambda: ks_jax.exchange_batch(*batch), args.repeats)
        row("exchange_batch, device in, NumPy out", f"{n / t:.3g} /s",
            f"{n / t / base:.2f} of the kernel" if base else "")
        if "to_host" in inspect.signature(ks_jax.exchange_batch).parameters:
            t = median_time(blocking(ks_jax.exchange_batch, *batch, to_host=False), args.repeats)
            row("exchange_batch, device in, device out", f"{n / t:.3g} /s",
                f"{n / t / base:.2f} of the kernel" if base else "")
        if args.profile:
            kernel_table(lambda: ks_jax.exchange_batch(*host), f"exchange_batch, {n} rows", args.profile)
    batch = host = None  # free the rows before the sweep
    if "sweep" in only:
        case = ks_jax.load_case(CASE)
        side = int(round(args.sweep ** 0.5))
        over = {"vehicles[1].speed": np.linspace(5.0, 35.0, side), "contact.restitution": np.linspace(0.0, 0.5, side)}
        ks_jax.sweep(case, over, keep=False, progress=False)
        t = time.perf_counter()
        r = ks_jax.sweep(case, over, keep=False, progress=False)
        wall = time.perf_counter() - t
        base = kernel_rate.get("float64")
        row(f"sweep, {side}^2 points, keep=False", f"{side * side / wall:.3g} /s",
            f"{wall:.2f} s" + (f"; {side * side / wall / base:.2f} of the kernel" if base else ""))
        small = {k: v[: max(2, side // 10)] for k, v in over.items()}
        ks_jax.sweep(case, small, progress=False)
        t = time.perf_counter()
        ks_jax.sweep(case, small, progress=False)
        wall = time.perf_counter() - t
        m = len(small["vehicles[1].speed"]) ** 2
        row(f"sweep, {m} points, default outputs kept", f"{m / wall:.3g} /s",
            f"{wall:.2f} s; statuses {r.status_counts}")
    if "grad" in only:
        m = min(n, 1 << 20)
        _, rows = random_batch(m, seed=1)

        def one(*a):
            r = ks_jax.exchange(*a)
            return jnp.where(r.contact.status == 0, delta_v(r), 0.0)

        loss = ks_jax.sum_over_rows(one)
        fwd = jax.jit(loss)
        vg = jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2, 3, 4)))
        t_f = median_time(blocking(fwd, *rows), args.repeats)
        t_g = median_time(blocking(vg, *rows), args.repeats)
        row(f"gradient / forward, sum_over_rows, {m} rows", f"{t_g / t_f:.2f}", f"forward {m / t_f:.3g} rows/s")
    if "fit" in only:
        cases, truths, evidence, unknowns, chi2 = bench_fit.sliding_cases(args.fits, 0)
        t = time.perf_counter()
        fit.reconstruct_batch(cases, unknowns, evidence, starts=8, smoothing=bench_fit.SMOOTHING)
        first = time.perf_counter() - t

        def second_call():
            return fit.reconstruct_batch(cases, unknowns, evidence, starts=8, seed=1, smoothing=bench_fit.SMOOTHING)

        with bench_fit.recording([]) as calls:
            t = time.perf_counter()
            results = second_call()
            second = time.perf_counter() - t
        s = bench_fit.score(results, truths, chi2)
        host = bench_fit.host_seconds(calls, second_call)
        with bench_fit.solver_work() as work:
            second_call()
        row(f"reconstruct_batch, {args.fits} x 8 starts", f"{second:.3f} s",
            f"first call {first:.1f} s; global {100 * s['global']:.1f}%, coverage {100 * s['coverage']:.1f}%; "
            f"host work {host:.3f} s ({1e3 * host / args.fits:.3f} ms per fit, solver's calls replayed); "
            f"{bench_fit.work_note(work)}")
        if args.profile:
            kernel_table(lambda: fit.reconstruct_batch(cases, unknowns, evidence, starts=8, seed=2,
                                                       smoothing=bench_fit.SMOOTHING), f"fits {args.fits} x 8",
                         args.profile)
        if args.many:
            many_fits(args, bench_fit.repeated(args.many, cases, unknowns, evidence), row)
    if "motion" in only:
        motions_to_rest(args, row)
    print(f"\n{dev.device_kind}, {date}\n| what | figure | note |\n|---|---|---|")
    print("\n".join(table))


if __name__ == "__main__":
    main()
