"""The batched exchange beside its baselines: throughput, gradients of batched losses, sweeps. Not a test.

    .venv/bin/python benchmarks/bench_kernel.py [--rows 1048576] [--repeats 5] [--grid 1000]
        [--memory-n 10000] [--sharded-n 1000] [--naive-rows 1048576]

Prints the machine, the command and the date, then, measured in --repeats rounds that run every variant
once in turn (rates: the median time; ratios: the median of the ratios within a round, so that a change
in the machine's load moves both sides of a ratio alike), over --rows random rows around the seed case
(batch-first, every result computed):

- exchanges/s of ``jax.jit(jax.vmap(ks_jax.exchange))`` (on one CPU device its vmap rule runs the
  exchange's three stages in chunks of 16384 rows inside one program) and of ``ks_jax.exchange_batch``
  (one program per chunk, each chunk copied into batch-sized NumPy arrays; and with ``out=`` an earlier
  result, which touches no new memory), float64 and float32; and of the whole-batch program,
  ``jax.jit(jax.vmap(ks_jax.model.collision.exchange))`` (the physics function without the chunked rule);
- a plain vectorized NumPy implementation of the same equations (benchmarks/numpy_ks.py, float64);
- memory streaming over the same bytes: a jitted x * 1.0 + 0 over arrays as large as the inputs and
  results together (one read and one write of each), into new arrays and, donated, over its own inputs
  (no new memory: the reference for ``out=``); each in float64, and in float32 for the float32 rows;
- the ratios to NumPy and to streaming, and the minor page faults per call (new memory touched);
- gradient / forward of two batched losses (the sum of both delta-V magnitudes, whose forward needs
  little more than the impulse; a reconstruction-style sum of squared residuals of delta-V, speed,
  course, PDOF and yaw rate after impact), rows whose status is not OK masked, ``jax.value_and_grad`` over
  every input against the loss's own forward: built with ``ks_jax.sum_over_rows`` (each chunk's value
  and gradient in one program), written over ``jax.vmap(ks_jax.exchange)`` (the derivatives of
  ``jax.vmap`` over the whole batch) and over the whole-batch program; and the gradients against each
  other and against ``jit(vmap(exchange))`` computing every result; first calls (compile + run);
- a sweep of a --grid x --grid grid (``ks_jax.sweep``, default outputs; the median of at least 3 calls);
- in fresh processes afterwards: the time and peak memory of a sweep of --memory-n^2 points
  (``bench_sweep_memory.py``, one output kept as float32, then nothing kept), a --sharded-n^2 grid over
  two forced host devices against one (``bench_sweep_sharded.py``), and the naive ``jit(vmap)`` with
  batched 3x3 LAPACK solves (``bench_naive.py``); a size of 0 skips each;
- the per-call cost of pycrash's planar impulse function ``impc_calcs`` if pycrash imports
  (PYCRASH_PATH=DIR adds a throwaway install: ``pip install --target DIR pycrash``).

It ends with a summary of the figures that benchmarks/README.md quotes.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import importlib.util
import io
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy_ks

import ks_jax
from ks_jax.case import as_arrays, to_pytrees
from ks_jax.model import collision

CASE = Path(ks_jax.__file__).parent / "cases" / "seed_000_saturn_pontiac.json"


def cpu_model():
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def first_call(fn):
    """Seconds of the first call of fn() (compile + run; fn blocks until done)."""
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def process_usage():
    """(CPU seconds, user and system, of all threads; minor page faults) of this process so far. A minor
    fault is a new 4 KiB page touched for the first time (a batch-sized result in new memory)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime, r.ru_minflt


def rounds(fns, repeats, usage=None):
    """Times of each fn() (blocking), in ``repeats`` rounds that run every fn once, in turn, so that a
    ratio of two of them can be taken round by round (``ratio``). ``usage``: a dict that gets, per fn, the
    (CPU seconds, minor page faults) of this process during each call."""
    times = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            u0 = process_usage()
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
            if usage is not None:
                usage.setdefault(name, []).append(tuple(b - a for a, b in zip(u0, process_usage())))
    return times


def ratio(times, a, b):
    """Median over rounds of time[b] / time[a] (how many times faster a is than b)."""
    return statistics.median(tb / ta for ta, tb in zip(times[a], times[b]))


def random_batch(n, seed=0):
    """n rows around the seed case (speeds, angles, contact point, (3, 3) inertias, restitution and
    friction varied): batch-first NumPy dicts (for numpy_ks and naive_ks) and the same rows as
    ``ks_jax`` pytrees of JAX arrays, batch-first."""
    rng = np.random.default_rng(seed)
    v1, s1, v2, s2, c = (jax.tree_util.tree_map(np.asarray, t)
                         for t in to_pytrees(as_arrays(ks_jax.load_case(CASE).inputs)))

    def rows(x, rel=0.1):
        x = np.asarray(x, dtype=np.float64)
        return x[None] * (1 + rel * rng.standard_normal((n,) + x.shape))

    def veh(v):
        inertia = np.diag(np.diag(v.inertia))[None] * np.abs(1 + 0.2 * rng.standard_normal((n, 3, 3)))
        off = 0.03 * rng.standard_normal((n, 3)) * np.diag(v.inertia).min()
        for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
            inertia[:, i, j] = inertia[:, j, i] = off[:, k]
        return {"mass": rows(v.mass), "inertia": inertia, "length": rows(v.length, 0.02),
                "width": rows(v.width, 0.02), "height": rows(v.height, 0.02),
                "cg_to_front": rows(v.cg_to_front, 0.02), "cg_height": rows(v.cg_height, 0.02)}

    def st(s):
        yaw = s.yaw + 0.3 * rng.standard_normal(n)
        speed = np.linalg.norm(s.velocity) * (1 + 0.3 * rng.standard_normal(n))
        vel = np.stack([speed * np.cos(yaw), speed * np.sin(yaw), np.zeros(n)], -1)
        w = np.stack([np.zeros(n), np.zeros(n), 0.3 * rng.standard_normal(n)], -1)
        return {"position": rows(s.position, 0.02), "velocity": vel, "yaw": yaw,
                "pitch": 0.01 * rng.standard_normal(n), "roll": 0.01 * rng.standard_normal(n),
                "angular_velocity": w}

    az = 0.2 * rng.standard_normal(n)
    cn = {"point": rows(c.point, 0.05), "normal": np.stack([np.cos(az), np.sin(az), np.zeros(n)], -1),
          "restitution": rng.uniform(0, 0.5, n), "friction": rng.uniform(0.1, 1.0, n),
          "penetration_time": np.zeros(n)}
    nps = (veh(v1), st(s1), veh(v2), st(s2), cn)
    kinds = (ks_jax.Vehicle, ks_jax.State, ks_jax.Vehicle, ks_jax.State, ks_jax.Contact)
    first = tuple(k(**{f: jnp.asarray(d[f]) for f in k._fields}) for k, d in zip(kinds, nps))
    return nps, jax.block_until_ready(first)


def nbytes(tree):
    return sum(x.size * x.dtype.itemsize for x in jax.tree_util.tree_leaves(tree))


def streaming_references(inputs, outputs, dtype=jnp.float64):
    """Two streaming references over the arrays of ``inputs`` and ``outputs``, cast to ``dtype``:
    (stream, stream_in_place, bytes). ``stream`` computes x * 1.0 + 0 of every array into new ones;
    ``stream_in_place`` writes each result over its input (donated), with no new memory, as
    ``exchange_batch(out=)`` does. The 1 and 0 are arguments: as constants XLA would make the program the
    identity, and a donated identity moves no bytes at all."""
    flat = [jnp.asarray(x).astype(dtype) for x in jax.tree_util.tree_leaves((inputs, outputs))]
    copy = jax.jit(lambda xs: [x * 1.0 + 0 for x in xs])
    copy_in_place = jax.jit(lambda xs, a, b: [x * a + b for x in xs], donate_argnums=0)
    held = [[jnp.array(x) for x in flat]]
    one_zero = jnp.asarray(1.0, dtype), jnp.asarray(0.0, dtype)

    def stream():
        return jax.block_until_ready(copy(flat))

    def stream_in_place():
        held[0] = jax.block_until_ready(copy_in_place(held[0], *one_zero))

    return stream, stream_in_place, sum(x.size * x.dtype.itemsize for x in flat)


def pycrash_rate(repeats):
    """Seconds per call of pycrash.impc.impc_calcs, or a reason why not."""
    extra = os.environ.get("PYCRASH_PATH")
    if extra:
        sys.path.insert(0, extra)
    spec = importlib.util.find_spec("pycrash")
    if spec is None:
        return None, "pycrash not available (pip install --target DIR pycrash, then PYCRASH_PATH=DIR)"
    path = Path(spec.submodule_search_locations[0]) / "impc.py"
    try:  # load impc.py alone: the package __init__ pulls plotting/dash dependencies
        mspec = importlib.util.spec_from_file_location("pycrash_impc", path)
        mod = importlib.util.module_from_spec(mspec)
        mspec.loader.exec_module(mod)
    except Exception as err:  # noqa: BLE001
        return None, f"pycrash not available: {path} does not load ({err})"
    veh = lambda **kw: types.SimpleNamespace(**kw)  # noqa: E731
    v1 = veh(head_angle=0.0, pimpact_x=-7.0, pimpact_y=0.0, vx_initial=7.33, vy_initial=0.0, omega_z=0.0,
             weight=3183.475, izz=1770.0)
    v2 = veh(head_angle=0.0, pimpact_x=7.0, pimpact_y=0.0, vx_initial=30.8, vy_initial=0.0, omega_z=0.0,
             weight=3496.531, izz=1990.0)
    sim = {"cor": 0.1, "cof": 0.5, "impact_norm_deg": 0.0}
    n = 2000
    sink = io.StringIO()
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        with contextlib.redirect_stdout(sink):  # it prints several lines per call
            for _ in range(n):
                mod.impc_calcs(v1, v2, 7.0, 0.0, sim)
        runs.append((time.perf_counter() - t) / n)
        sink.seek(0)
        sink.truncate()
    return statistics.median(runs), "pycrash.impc.impc_calcs (planar, scalar Python, prints redirected)"


def delta_v(r):
    """Both delta-V magnitudes (the forward needs little more than the impulse)."""
    return r.vehicles[0].delta_v_magnitude + r.vehicles[1].delta_v_magnitude


def residuals(r):
    """Squared residuals against made-up evidence; angles compared on the circle."""
    total = 0.0
    for k, v in enumerate(r.vehicles):
        total = total + (v.delta_v_magnitude - 5.0) ** 2 + (v.speed_after - 8.0) ** 2 \
            + (1 - jnp.cos(jnp.radians(v.course_after - 10.0))) \
            + (1 - jnp.cos(jnp.radians(v.pdof - 30.0 * k))) + (v.yaw_rate_after - 0.1) ** 2
    return total


LOSSES = {"delta-V": delta_v, "residuals": residuals}
WAYS = ("sum_over_rows", "vmap(exchange)", "whole-batch")


def batched_loss(row_loss, way="vmap(exchange)"):
    """The sum over the rows whose status is OK of ``row_loss`` of a row's results, as a function of the
    five batch-first input pytrees: built with ``ks_jax.sum_over_rows`` ("sum_over_rows"), written over
    ``jax.vmap(ks_jax.exchange)`` ("vmap(exchange)") or over ``jax.vmap(ks_jax.model.collision.exchange)``
    ("whole-batch": no chunked vmap rule)."""
    if way == "sum_over_rows":
        def row(*a):
            r = ks_jax.exchange(*a)
            return jnp.where(r.contact.status == 0, row_loss(r), 0.0)
        return ks_jax.sum_over_rows(row)
    fn = {"vmap(exchange)": ks_jax.exchange, "whole-batch": collision.exchange}[way]

    def loss(*args):
        r = jax.vmap(fn)(*args)
        return jnp.sum(jnp.where(r.contact.status == 0, row_loss(r), 0.0))
    return loss


def run_script(name, *argv, **env):
    """The last line a benchmark script beside this one prints, run in a process of its own (its peak
    memory is then its own, and XLA_FLAGS apply to it alone)."""
    done = subprocess.run([sys.executable, str(Path(__file__).resolve().parent / name), *argv],
                          env=dict(os.environ, **env), capture_output=True, text=True)
    if done.returncode != 0:
        return f"failed (exit {done.returncode}): {done.stderr.strip().splitlines()[-1:]}"
    return done.stdout.strip().splitlines()[-1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--grid", type=int, default=1000, help="sweep grid side (default 1000: 10^6 points)")
    ap.add_argument("--memory-n", type=int, default=10000, help="grid side of the peak-memory sweep (10^8 points)")
    ap.add_argument("--sharded-n", type=int, default=1000, help="grid side of the sharded sweep")
    ap.add_argument("--naive-rows", type=int, default=1 << 20, help="rows of the naive baseline (bench_naive.py)")
    args = ap.parse_args()
    n, reps = args.rows, args.repeats

    print("ks-jax kernel benchmark")
    print(f"  date     {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC")
    print(f"  command  {' '.join([Path(sys.executable).name, *sys.argv])}")
    print(f"  machine  {cpu_model()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"  jax      {jax.__version__}, backend {jax.default_backend()}, devices {jax.devices()}")
    print(f"  numpy    {np.__version__}")
    print(f"  rows     {n} per batch, batch-first, {reps} interleaved rounds (medians)\n", flush=True)

    nps, first = random_batch(n)
    first32 = jax.block_until_ready(jax.tree_util.tree_map(lambda x: x.astype(jnp.float32), first))
    vmapped = jax.jit(jax.vmap(ks_jax.exchange))
    whole = jax.jit(jax.vmap(collision.exchange))

    # --- first calls (compile + run), then every forward in interleaved rounds
    firsts = {
        "batch64": first_call(lambda: ks_jax.exchange_batch(*first)),
        "batch32": first_call(lambda: ks_jax.exchange_batch(*first32)),
        "vmap64": first_call(lambda: jax.block_until_ready(vmapped(*first))),
        "vmap32": first_call(lambda: jax.block_until_ready(vmapped(*first32))),
        "whole": first_call(lambda: jax.block_until_ready(whole(*first))),
    }
    out = ks_jax.exchange_batch(*first)
    out32 = ks_jax.exchange_batch(*first32)
    stream, stream_in_place, stream_bytes = streaming_references(first, out)
    stream32, stream32_in_place, stream32_bytes = streaming_references(first32, out32, jnp.float32)
    fns = {
        "vmap64": lambda: jax.block_until_ready(vmapped(*first)),
        "batch64": lambda: ks_jax.exchange_batch(*first),
        "batch64out": lambda: ks_jax.exchange_batch(*first, out=out),
        "vmap32": lambda: jax.block_until_ready(vmapped(*first32)),
        "batch32": lambda: ks_jax.exchange_batch(*first32),
        "whole": lambda: jax.block_until_ready(whole(*first)),
        "numpy": lambda: numpy_ks.exchange(*nps),
        "stream": stream,
        "stream_in_place": stream_in_place,
        "stream32": stream32,
        "stream32_in_place": stream32_in_place,
    }
    for fn in fns.values():  # warm
        fn()
    usage = {}
    times = rounds(fns, reps, usage)
    rate = {k: n / statistics.median(v) for k, v in times.items()}
    q = lambda a, b: ratio(times, a, b)  # noqa: E731

    def largest_difference(a, b):
        return max(float(np.nanmax(np.abs(np.asarray(x, np.float64) - np.asarray(y, np.float64))))
                   for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b))
                   if np.asarray(x).dtype.kind == "f")

    same_vmap = largest_difference(out, vmapped(*first))
    same_whole = largest_difference(out, whole(*first))
    statuses = np.bincount(np.asarray(out.contact.status).ravel())
    ref_c, ref_v = numpy_ks.exchange(*jax.tree_util.tree_map(lambda x: x[:4096], nps))
    valid = np.asarray(out.contact.status[:4096]) == 0
    agree = max(
        np.max(np.abs(np.asarray(out.contact.impulse_magnitude[:4096]) - ref_c["impulse_magnitude"])[valid]
               / np.abs(ref_c["impulse_magnitude"])[valid]),
        np.max(np.abs(np.asarray(out.vehicles[1].delta_v_magnitude[:4096]) - ref_v[1]["delta_v_magnitude"])[valid]
               / np.abs(ref_v[1]["delta_v_magnitude"])[valid]),
    )
    agree32 = max(float(np.nanmax(np.abs(np.asarray(a, np.float64) - np.asarray(b))
                                  / np.maximum(np.abs(np.asarray(b)), 1.0)))
                  for a, b in ((out32.contact.impulse_magnitude, out.contact.impulse_magnitude),
                               (out32.vehicles[1].delta_v_magnitude, out.vehicles[1].delta_v_magnitude)))

    w = 46
    print(f"{'forward, ' + str(n) + ' rows':{w}} {'exchanges/s':>12}  {'/NumPy':>7}  {'/stream':>7}  first call")
    for key, label, against in (("vmap64", "jit(vmap(exchange)) float64", "stream"),
                                ("batch64", "exchange_batch float64", "stream"),
                                ("batch64out", "exchange_batch float64, out= (no new memory)", "stream_in_place"),
                                ("vmap32", "jit(vmap(exchange)) float32", "stream32"),
                                ("batch32", "exchange_batch float32", "stream32"),
                                ("whole", "whole-batch jit(vmap(collision.exchange))", "stream"),
                                ("numpy", "NumPy vectorized (numpy_ks.py) float64", "stream"),
                                ("stream", "stream x*1.0+0, float64, new arrays", "stream"),
                                ("stream_in_place", "same, in place (donated)", "stream_in_place"),
                                ("stream32", "stream x*1.0+0, float32, new arrays", "stream32"),
                                ("stream32_in_place", "same, in place (donated)", "stream32_in_place")):
        f = f"{firsts[key]:.2f} s" if key in firsts else ""
        print(f"{label:{w}} {rate[key]:12.4g}  {q(key, 'numpy'):7.2f}  {q(key, against):7.3f}  {f}")
    print(f"(/stream: against the streaming row of the same dtype, in place for out=; {nbytes(first) + nbytes(out)} "
          f"bytes in + out, {(nbytes(first) + nbytes(out)) / n:.0f} B/row; streaming float64 "
          f"{stream_bytes / statistics.median(times['stream']) / 1e9:.2f} GB/s read, as much written; "
          f"float32 {stream32_bytes / statistics.median(times['stream32']) / 1e9:.2f} GB/s)")
    print(f"jit(vmap(exchange)) / exchange_batch {q('vmap64', 'batch64'):.2f} (float64), {q('vmap32', 'batch32'):.2f} "
          f"(float32); float32 / float64: jit(vmap) {q('vmap32', 'vmap64'):.2f}, exchange_batch "
          f"{q('batch32', 'batch64'):.2f}; jit(vmap(exchange)) / whole-batch {q('vmap64', 'whole'):.2f}")
    print(f"largest differences from exchange_batch: jit(vmap(exchange)) {same_vmap:.1e}, "
          f"whole-batch {same_whole:.1e}; NumPy agrees to {agree:.1e} (relative, valid rows of the first 4096); "
          f"float32 to float64 {agree32:.1e}")
    faults = lambda k: f"{statistics.median(u[1] for u in usage[k]):.0f}"  # noqa: E731
    print(f"page faults per call (medians): exchange_batch {faults('batch64')}, out= {faults('batch64out')}, "
          f"jit(vmap(exchange)) {faults('vmap64')}, whole-batch {faults('whole')}, NumPy {faults('numpy')}, "
          f"streaming {faults('stream')}, in place {faults('stream_in_place')}, float32 {faults('stream32')}, "
          f"in place {faults('stream32_in_place')}; a float64 result is "
          f"{nbytes(out) / 4096:.0f} pages of 4 KiB")
    print(f"statuses in the random batch: {dict((int(k), int(v)) for k, v in enumerate(statuses) if v)}\n", flush=True)

    # --- gradient / forward of the two batched losses, each way, batch-first; the forward section's arrays
    # (float32 rows, results, streaming copies: gigabytes) freed first
    every_result = fns["vmap64"]
    del fns, stream, stream_in_place, stream32, stream32_in_place
    first32 = out32 = None
    gfns, gfirst, finite = {}, {}, {}
    for name, row_loss in LOSSES.items():
        for way in WAYS:
            loss = batched_loss(row_loss, way)
            fwd, grad = jax.jit(loss), jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2, 3, 4)))
            first_call(lambda: jax.block_until_ready(fwd(*first)))
            gfirst[(name, way)] = first_call(lambda: jax.block_until_ready(grad(*first)))
            g = grad(*first)[1]
            finite[(name, way)] = all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(g))
            del g
            gfns[(name, way, "forward")] = lambda fwd=fwd: jax.block_until_ready(fwd(*first))
            gfns[(name, way, "gradient")] = lambda grad=grad: jax.block_until_ready(grad(*first))
    gfns[("every result",)] = every_result  # the forward computing every result, in the same rounds
    gusage = {}
    gt = rounds(gfns, reps, gusage)
    gq = lambda a, b: ratio(gt, a, b)  # noqa: E731
    print(f"{'gradient, ' + str(n) + ' rows':{w}} {'rows/s':>12}  {'grad/fwd':>8}  "
          "forward rows/s, first call of the gradient")
    grads = {}
    for name in LOSSES:
        for way in WAYS:
            f, g = (name, way, "forward"), (name, way, "gradient")
            grads[(name, way)] = gq(f, g)
            print(f"{name + ', ' + way:{w}} {n / statistics.median(gt[g]):12.4g}  {grads[(name, way)]:8.2f}  "
                  f"{n / statistics.median(gt[f]):.4g}/s, {gfirst[(name, way)]:.2f} s, gradient finite: "
                  f"{finite[(name, way)]}")
        so, vm, wh = ((name, way, "gradient") for way in WAYS)
        print(f"  {name}: page faults per gradient call (medians): " + ", ".join(
            f"{way} {statistics.median(u[1] for u in gusage[(name, way, 'gradient')]):.0f}" for way in WAYS))
        print(f"  {name}: gradient through vmap(exchange) / sum_over_rows {gq(so, vm):.2f}, whole-batch / "
              f"sum_over_rows {gq(so, wh):.2f}; sum_over_rows gradient / jit(vmap(exchange)) every result "
              f"{gq(('every result',), so):.2f}")
    print(flush=True)

    # --- a sweep of a grid
    case = ks_jax.load_case(CASE)
    over = {"vehicles[1].speed": np.linspace(2, 30, args.grid), "contact.friction": np.linspace(0, 1, args.grid)}
    tsw_first = first_call(lambda: ks_jax.sweep(case, over, progress=False))
    sweeps = [ks_jax.sweep(case, over, progress=False) for _ in range(max(reps, 3))]
    tsw = statistics.median(x.seconds for x in sweeps)
    print(f"sweep {args.grid} x {args.grid}, {len(sweeps[-1].output_paths)} outputs + status: {tsw:.2f} s "
          f"({sweeps[-1].points / tsw:.3g} points/s; median of {len(sweeps)} calls, "
          f"{min(x.seconds for x in sweeps):.2f}-{max(x.seconds for x in sweeps):.2f} s; first call {tsw_first:.2f} s)",
          flush=True)

    pc, pc_note = pycrash_rate(3)
    if pc is None:
        print(pc_note)
    else:
        print(f"pycrash impc_calcs: {pc * 1e6:.1f} us per call ({1 / pc:.3g} exchanges/s; exchange_batch is "
              f"{rate['batch64'] * pc:.0f}x) -- {pc_note}")

    extra = []
    if args.memory_n:
        for keep in ("float32", "none"):
            extra.append(("sweep memory", run_script("bench_sweep_memory.py", "--n", str(args.memory_n),
                                                     "--keep", keep)))
            print(f"bench_sweep_memory.py --n {args.memory_n} --keep {keep}: {extra[-1][1]}", flush=True)
    if args.sharded_n:
        extra.append(("sharded", run_script("bench_sweep_sharded.py", "--n", str(args.sharded_n),
                                            XLA_FLAGS="--xla_force_host_platform_device_count=2")))
        print(f"bench_sweep_sharded.py --n {args.sharded_n} (2 forced host devices): {extra[-1][1]}", flush=True)
    if args.naive_rows:
        extra.append(("naive", run_script("bench_naive.py", "--rows", str(args.naive_rows), "--repeats", str(reps))))
        print(f"bench_naive.py --rows {args.naive_rows}: {extra[-1][1]}", flush=True)

    print("\nsummary (medians of the rounds above):")
    for key, label in (("vmap64", "jit(vmap(exchange)) float64"), ("batch64", "exchange_batch float64"),
                       ("vmap32", "jit(vmap(exchange)) float32"), ("batch32", "exchange_batch float32")):
        against = "stream32" if key.endswith("32") else "stream"
        print(f"  {label:28} {rate[key]:.3g} exchanges/s, {q(key, 'numpy'):.1f}x NumPy float64, "
              f"{q(key, against):.2f} of streaming into new arrays, {q(key, against + '_in_place'):.2f} in place "
              f"({'float32' if key.endswith('32') else 'float64'})")
    for name in LOSSES:
        print(f"  gradient/forward, {name:9}  sum_over_rows {grads[(name, 'sum_over_rows')]:.2f}, "
              f"vmap(exchange) {grads[(name, 'vmap(exchange)')]:.2f}, whole-batch {grads[(name, 'whole-batch')]:.2f}")
    print(f"  sweep {args.grid} x {args.grid}             {tsw:.2f} s")


if __name__ == "__main__":
    main()
