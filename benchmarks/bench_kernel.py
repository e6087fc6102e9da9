"""Benchmark of the batched KS kernel, side by side with its baselines. Not a test.

    .venv/bin/python benchmarks/bench_kernel.py [--rows 1048576] [--repeats 5] [--grid 1000]

Prints the machine, the command and the date, then, measured in --repeats rounds that run every
variant once in turn (rates: the median time; ratios: the median of the ratios within a round, so
that a change in the machine's load moves both sides of a ratio alike):
- the kernel's rate (exchanges/s, all section-4 results, float64 and float32) as the library
  computes a batch: ``ks_jax.exchange_batch`` (batch-first inputs, chunks of 16384 rows, three
  jitted calls per chunk: ``exchange.prepare``, which also copies the chunk's rows for the other
  two, ``exchange.impulse_stage``, ``exchange.results_stage``, each chunk's results copied into
  batch-sized NumPy arrays; and the same writing into the arrays of an earlier result (``out=``),
  which needs no new memory;
  ``ks_jax.sweep`` does the same per chunk); ``jit(vmap(exchange))``, batch-last and batch-first
  (on one CPU device its vmap rule runs the same three stages in chunks inside one loop); and for
  comparison the whole-batch program that vmap made of ``exchange`` before that rule (``jit(vmap)`` of
  ``exchange_with_status`` after ``input_status``, batch-first);
- a plain vectorized NumPy implementation of the same equations (benchmarks/numpy_ks.py);
- the memory-streaming rate of the same bytes: a jitted x * 1.0 + 0 over arrays as large as the
  kernel's inputs and outputs together (one read and one write of each, as the kernel does), into
  new arrays and, donated, over its own inputs (no new memory: against ``out=``);
- the minor page faults per call (new memory touched), and jit(vmap(exchange)) / NumPy round by
  round, with that call's CPU time per row and page faults (to tell what made a round slow);
- the ratios kernel/NumPy and kernel/streaming; gradient / forward of two batched losses, each
  against its own forward (``jax.value_and_grad`` of ``sum(vmap(exchange))`` over every input), with
  the batch axis first (``jax.vmap``'s default) and last:
  the sum of both delta-V magnitudes (the forward needs only the impulse) and a
  reconstruction-style sum of squared residuals of delta-V, speed, course, PDOF and yaw rate
  after impact, through ``exchange_with_status`` (one whole-batch program, forward and gradient
  alike) and, batch-first, through ``exchange`` (forward and gradient in chunks, with the
  whole-batch gradient / the chunked one, and the chunked gradient / ``jit(vmap(exchange))``
  computing every result, timed in the same rounds: a loss's forward computes only what the loss
  reads, the delta-V one little more than the impulse), and, batch-first, the same losses built by
  ``ks_jax.sum_over_rows`` (the same forward; the gradient each chunk's value and gradient in one
  program), with the gradient through ``exchange`` / this one; the first-call (compile) times;
- a sweep of a 1000 x 1000 grid (``ks_jax.sweep``, default outputs; the median of ``--repeats`` calls,
  at least 3);
- in fresh processes, after everything above: the time and peak memory of a sweep of 10^8 points
  (``bench_sweep_memory.py``, one output kept as float32, then nothing kept; ``--memory-n 0``
  skips it) and a 1000 x 1000 grid sharded over two forced host devices against one device
  (``bench_sweep_sharded.py`` under ``XLA_FLAGS=--xla_force_host_platform_device_count=2``;
  ``--sharded-n 0`` skips it), and issue #5's naive baseline, ``jit(vmap)`` with batched 3x3 LAPACK
  solves, beside NumPy, both streaming references and the library, with its gradient / forward
  (``bench_naive.py``; ``--naive-rows 0`` skips it);
- the per-call cost of pycrash's planar impulse function ``impc_calcs`` if pycrash imports
  (PYCRASH_PATH=dir adds a throwaway install, e.g. ``pip install --target dir pycrash``).
Batch-last (every leaf (..., N)) makes each component of a vector one contiguous array, which is
what XLA's elementwise loops want in the forward; the gradients' cotangents of (3, 3) inputs are
then transposed (benchmarks/RESULTS.md: the delta-V gradient ran faster batch-first, the residual
one did not).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import importlib.util
import io
import os
import platform
import re
import resource
import statistics
import sys
import time
import types
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy_ks  # noqa: E402

import ks_jax  # noqa: E402
from ks_jax.case import as_arrays, to_pytrees  # noqa: E402
from ks_jax.batch import exchange_batch  # noqa: E402
from ks_jax.exchange import exchange, exchange_with_status, input_status, prepare, results_stage, values_impulse_stage  # noqa: E402
from ks_jax.sweeps import sweep  # noqa: E402

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


def rounds(fns, repeats, usage=None):
    """Times of each fn() (blocking), measured in ``repeats`` rounds that run every fn once, in
    turn: a ratio of two of them is then taken round by round (``ratio``), so a change in the
    machine's load during the run moves both sides of it alike. ``usage``: a dict that gets, per
    fn, the (CPU seconds, minor page faults) of this process during each call (``process_usage``)."""
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


def process_usage():
    """(CPU seconds, user and system, of all threads; minor page faults) of this process so far.
    A call whose CPU time grows with its wall time was slowed down while it ran (the machine is
    shared: caches and memory bandwidth, not only cores). A minor fault is a new 4 KiB page touched for
    the first time (a batch-sized result in new memory); whether a call gets new memory depends on
    what the allocator kept from the calls before it."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime, r.ru_minflt


def ratio(times, a, b):
    """Median over rounds of time[b] / time[a] (how many times faster a is than b)."""
    return statistics.median(tb / ta for ta, tb in zip(times[a], times[b]))


def random_batch(n, seed=0):
    """Rows around the seed case: speeds, angles, contact point, inertias, eps and mu varied;
    batch-first NumPy dicts (for numpy_ks) and batch-last kernel pytrees."""
    rng = np.random.default_rng(seed)
    v1, s1, v2, s2, c = (jax.tree_util.tree_map(np.asarray, t) for t in to_pytrees(as_arrays(ks_jax.load_case(CASE).inputs)))

    def rows(x, rel=0.1):
        x = np.asarray(x, dtype=np.float64)
        return x[None] * (1 + rel * rng.standard_normal((n,) + x.shape))

    def veh(v):
        I = np.diag(np.diag(v.inertia))[None] * np.abs(1 + 0.2 * rng.standard_normal((n, 3, 3)))
        off = 0.03 * rng.standard_normal((n, 3)) * np.diag(v.inertia).min()
        for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
            I[:, i, j] = I[:, j, i] = off[:, k]
        return {"mass": rows(v.mass), "inertia": I, "length": rows(v.length, 0.02), "width": rows(v.width, 0.02),
                "height": rows(v.height, 0.02), "cg_to_front": rows(v.cg_to_front, 0.02),
                "cg_height": rows(v.cg_height, 0.02)}

    def st(s):
        yaw = s.yaw + 0.3 * rng.standard_normal(n)
        speed = np.linalg.norm(s.velocity) * (1 + 0.3 * rng.standard_normal(n))
        vel = np.stack([speed * np.cos(yaw), speed * np.sin(yaw), np.zeros(n)], -1)
        w = np.stack([np.zeros(n), np.zeros(n), 0.3 * rng.standard_normal(n)], -1)
        return {"position": rows(s.position, 0.02), "velocity": vel, "yaw": yaw, "pitch": 0.01 * rng.standard_normal(n),
                "roll": 0.01 * rng.standard_normal(n), "angular_velocity": w}

    az = 0.2 * rng.standard_normal(n)
    cn = {"point": rows(c.point, 0.05), "normal": np.stack([np.cos(az), np.sin(az), np.zeros(n)], -1),
          "restitution": rng.uniform(0, 0.5, n), "friction": rng.uniform(0.1, 1.0, n), "penetration_time": np.zeros(n)}
    nps = (veh(v1), st(s1), veh(v2), st(s2), cn)
    kinds = (ks_jax.Vehicle, ks_jax.State, ks_jax.Vehicle, ks_jax.State, ks_jax.Contact)
    last = tuple(k(**{f: jnp.asarray(np.moveaxis(d[f], 0, -1)) for f in k._fields}) for k, d in zip(kinds, nps))
    return nps, last


def batch_first(last):
    """``random_batch``'s batch-last pytrees with the batch axis first, as users hold a batch (JAX
    arrays, computed before this returns)."""
    return jax.block_until_ready(jax.tree_util.tree_map(lambda x: jnp.moveaxis(x, -1, 0), last))


def kernel_chunk():
    """What ``ks_jax.sweep`` computes per chunk, on batch-last inputs already cut into chunks
    (the sweep builds each chunk's inputs inside its first call): three jitted calls,
    ``exchange.prepare``, ``exchange.impulse_stage``, ``exchange.results_stage``."""
    v = lambda f: jax.vmap(f, in_axes=-1, out_axes=-1)  # noqa: E731
    prep = jax.jit(v(prepare))
    imp = jax.jit(v(values_impulse_stage(0.0)))
    body = jax.jit(v(results_stage))

    def run(args):
        status, trig = prep(*args)
        return body(*args, status, imp(*args, status, trig))

    return run


def kernel_one_call(axis=-1, whole=False):
    """``jit(vmap(exchange))``; ``whole``: the whole-batch program (no chunks)."""
    fn = (lambda *a: exchange_with_status(*a, 0.0, input_status(*a))) if whole else exchange
    f = jax.jit(jax.vmap(fn, in_axes=axis, out_axes=axis))
    return lambda args: f(*args)


def nbytes(tree):
    return sum(x.size * x.dtype.itemsize for x in jax.tree_util.tree_leaves(tree))


def streaming_references(inputs, outputs):
    """The two streaming references over the kernel's input and output arrays, as float64: (stream,
    stream_in_place, bytes). ``stream`` computes x * 1.0 + 0 of every array into new ones;
    ``stream_in_place`` writes each result over its input (donated), with no new memory, as
    ``exchange_batch(out=)``. Its 1 and 0 are arguments: as constants XLA would make the program the
    identity, and a donated identity moves no bytes at all."""
    flat = [jnp.asarray(x).astype(jnp.float64) for x in jax.tree_util.tree_leaves((inputs, outputs))]
    copy = jax.jit(lambda xs: [x * 1.0 + 0 for x in xs])
    copy_in_place = jax.jit(lambda xs, a, b: [x * a + b for x in xs], donate_argnums=0)
    held = [[jnp.array(x) for x in flat]]
    one_zero = jnp.float64(1.0), jnp.float64(0.0)

    def stream():
        return jax.block_until_ready(copy(flat))

    def stream_in_place():
        held[0] = jax.block_until_ready(copy_in_place(held[0], *one_zero))

    return stream, stream_in_place, sum(x.size * 8 for x in flat)


def pycrash_rate(repeats):
    """Seconds per call of pycrash.impc.impc_calcs, or a reason why not."""
    extra = os.environ.get("PYCRASH_PATH")
    if extra:
        sys.path.insert(0, extra)
    spec = importlib.util.find_spec("pycrash")
    if spec is None:
        return None, ("pycrash not available: not importable (pip install --target DIR pycrash, "
                      "then PYCRASH_PATH=DIR)")
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


def batched_loss(row_loss, axis, chunked=False, summed=False):
    """sum over valid rows of ``row_loss`` of the batch's results, as a function of (inputs, status):
    through ``exchange`` (``chunked``: its own status; on one CPU device its values and derivatives
    run in chunks), or through ``exchange_with_status`` (one whole-batch program, forward and
    gradient alike); ``summed``: built by ``ks_jax.sum_over_rows`` (batch-first; the forward is
    that of ``chunked``, the gradient each chunk's value and gradient in one program)."""
    if summed:
        def row(*a):
            r = exchange(*a)
            return jnp.where(r.contact.status == 0, row_loss(r), 0.0)
        total = ks_jax.sum_over_rows(row)
        return lambda args, status: total(*args)

    def loss(args, status):  # trig inside the differentiated function (it depends on the angles)
        if chunked:
            r = jax.vmap(exchange, in_axes=axis, out_axes=axis)(*args)
        else:
            r = jax.vmap(lambda *a: exchange_with_status(*a[:5], 0.0, a[5]), in_axes=axis, out_axes=axis)(*args, status)
        return jnp.sum(jnp.where(r.contact.status == 0, row_loss(r), 0.0))
    return loss


def delta_v(r):
    """Both delta-V magnitudes (the forward needs only the impulse)."""
    return r.vehicles[0].delta_v_magnitude + r.vehicles[1].delta_v_magnitude


def residuals(r):
    """Squared residuals against made-up evidence; angles compared on the circle."""
    total = 0.0
    for k, v in enumerate(r.vehicles):
        total = total + (v.delta_v_magnitude - 5.0) ** 2 + (v.speed_after - 8.0) ** 2 \
            + (1 - jnp.cos(jnp.radians(v.course_after - 10.0))) \
            + (1 - jnp.cos(jnp.radians(v.pdof - 30.0 * k))) + (v.yaw_rate_after - 0.1) ** 2
    return total


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
    print(f"  date     {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}")
    print(f"  command  {' '.join([Path(sys.executable).name, *sys.argv])}")
    print(f"  machine  {cpu_model()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}")
    print(f"  jax      {jax.__version__}, backend {jax.default_backend()}, devices {jax.devices()}")
    print(f"  numpy    {np.__version__}")
    print(f"  rows     {n} per batch, {reps} interleaved rounds (medians)\n")

    nps, last = random_batch(n)
    first = batch_first(last)
    one, one_first, whole = kernel_one_call(), kernel_one_call(0), kernel_one_call(0, whole=True)

    # --- first calls (compile + run), then everything in interleaved rounds
    first32 = jax.tree_util.tree_map(lambda x: x.astype(jnp.float32), first)
    chunk = 1 << 14
    chunks = [jax.tree_util.tree_map(lambda x: x[..., i:i + chunk], last) for i in range(0, n, chunk)]
    per_chunk = kernel_chunk()
    first64 = first_call(lambda: exchange_batch(*first))
    first32_s = first_call(lambda: exchange_batch(*first32))
    first1 = first_call(lambda: jax.block_until_ready(one(last)))
    first1f = first_call(lambda: jax.block_until_ready(one_first(first)))
    first_whole = first_call(lambda: jax.block_until_ready(whole(first)))
    out = exchange_batch(*first)
    io_bytes = nbytes(first) + nbytes(out)
    stream, stream_in_place, stream_bytes = streaming_references(first, out)
    fns = {
        "kernel64": lambda: exchange_batch(*first),
        "kernel32": lambda: exchange_batch(*first32),
        "kernel64out": lambda: exchange_batch(*first, out=out),
        "kernel1": lambda: jax.block_until_ready(one(last)),
        "kernel1f": lambda: jax.block_until_ready(one_first(first)),
        "whole": lambda: jax.block_until_ready(whole(first)),
        "chunk": lambda: jax.block_until_ready([per_chunk(a) for a in chunks]),
        "numpy": lambda: numpy_ks.exchange(*nps),
        "stream": stream,
        "stream_in_place": stream_in_place,
    }
    for fn in fns.values():  # warm
        fn()
    usage = {}
    times = rounds(fns, reps, usage)
    res = {k: n / statistics.median(v) for k, v in times.items()}
    t64 = statistics.median(times["kernel64"])
    tstream = statistics.median(times["stream"])
    statuses = np.bincount(np.asarray(out.contact.status).ravel())
    one_out = one(last)
    same = max(float(np.nanmax(np.abs(np.asarray(a) - np.moveaxis(np.asarray(b), -1, 0))))
               for a, b in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(one_out))
               if np.asarray(a).dtype.kind == "f")
    # NumPy agrees with the kernel (the invalid rows, NaN in both, are left out)
    ref_c, ref_v = numpy_ks.exchange(*jax.tree_util.tree_map(lambda x: x[:4096], nps))
    valid = np.asarray(out.contact.status[:4096]) == 0
    diff = max(
        np.max(np.abs(np.asarray(out.contact.impulse_magnitude[:4096]) - ref_c["impulse_magnitude"])[valid]
               / np.abs(ref_c["impulse_magnitude"])[valid]),
        np.max(np.abs(np.asarray(out.vehicles[1].delta_v_magnitude[:4096]) - ref_v[1]["delta_v_magnitude"])[valid]
               / np.abs(ref_v[1]["delta_v_magnitude"])[valid]),
    )

    # --- gradient / forward of two batched losses, in both layouts: batch-first (jax.vmap's default
    # in_axes=0, how exchange_batch takes its inputs) and batch-last
    gfns, firsts, finite = {}, {}, {}
    for layout, data, axis, chunked in (("batch-first", first, 0, False), ("batch-last", last, -1, False),
                                        ("exchange, batch-first", first, 0, True),
                                        ("sum_over_rows, batch-first", first, 0, "summed")):
        floats = tuple(data[:5])
        st = jax.jit(jax.vmap(input_status, in_axes=axis, out_axes=axis))(*data)
        for name, row_loss in (("delta-V", delta_v), ("residuals", residuals)):
            key = (name, layout)
            loss = batched_loss(row_loss, axis, bool(chunked), summed=chunked == "summed")
            fwd, grad = jax.jit(loss), jax.jit(jax.value_and_grad(loss))
            first_call(lambda: jax.block_until_ready(fwd(floats, st)))
            firsts[key] = first_call(lambda: jax.block_until_ready(grad(floats, st)))
            g = grad(floats, st)[1]
            finite[key] = all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(g))
            del g
            gfns[key + ("forward",)] = lambda fwd=fwd, floats=floats, st=st: jax.block_until_ready(fwd(floats, st))
            gfns[key + ("gradient",)] = lambda grad=grad, floats=floats, st=st: jax.block_until_ready(grad(floats, st))
    # the kernel's own forward (every result), in the same rounds: what the gradients cost against it
    gfns[("every result",)] = fns["kernel1f"]
    gt = rounds(gfns, reps)
    grads = {key: (statistics.median(gt[key + ("forward",)]), statistics.median(gt[key + ("gradient",)]),
                   ratio(gt, key + ("forward",), key + ("gradient",)), firsts[key], finite[key]) for key in firsts}

    # --- sweep of a million-point grid
    case = ks_jax.load_case(CASE)
    over = {"vehicles[1].speed": np.linspace(2, 30, args.grid), "contact.friction": np.linspace(0, 1, args.grid)}
    tsw_first = time.perf_counter()
    sweep(case, over, progress=False)
    tsw_first = time.perf_counter() - tsw_first
    sweeps = [sweep(case, over, progress=False) for _ in range(max(reps, 3))]  # the median of several calls
    r, tsw = sweeps[-1], statistics.median(x.seconds for x in sweeps)
    tsw_range = (min(x.seconds for x in sweeps), max(x.seconds for x in sweeps))

    pc, pc_note = pycrash_rate(3)

    w = 44
    q = lambda a, b: ratio(times, a, b)  # noqa: E731
    print(f"{'':{w}} {'exchanges/s':>14}  {'ratio':>8}")
    print(f"{'kernel float64 (exchange_batch)':{w}} {res['kernel64']:14.4g}")
    print(f"{'same, out= an earlier result (no new memory)':{w}} {res['kernel64out']:14.4g}  "
          f"{q('kernel64out', 'kernel64'):8.2f}  (/kernel; kernel/NumPy {q('kernel64out', 'numpy'):.2f})")
    print(f"{'kernel float32 (same)':{w}} {res['kernel32']:14.4g}  {q('kernel32', 'kernel64'):8.2f}  (f32/f64)")
    print(f"{'jit(vmap(exchange)), batch-last':{w}} {res['kernel1']:14.4g}  {q('kernel1', 'kernel64'):8.2f}  "
          f"(/kernel; largest difference {same:.1e}; first call {first1:.2f} s)")
    print(f"{'same, batch-first (jax.vmap default)':{w}} {res['kernel1f']:14.4g}  {q('kernel1f', 'kernel64'):8.2f}  "
          f"(/kernel; first call {first1f:.2f} s)")
    print(f"{'whole-batch jit(vmap), batch-first':{w}} {res['whole']:14.4g}  {q('whole', 'kernel64'):8.2f}  "
          f"(/kernel; jit(vmap(exchange)) batch-first is {q('kernel1f', 'whole'):.2f}x it; first call {first_whole:.2f} s)")
    print(f"{'sweep path: chunks of 16384, batch-last':{w}} {res['chunk']:14.4g}  {q('chunk', 'kernel64'):8.2f}  "
          f"(/kernel; the three calls on inputs already cut into chunks)")
    print(f"{'NumPy vectorized, same equations, float64':{w}} {res['numpy']:14.4g}  "
          f"{q('kernel64', 'numpy'):8.2f}  (kernel/NumPy; agree to {diff:.1e}; sweep path/NumPy "
          f"{q('chunk', 'numpy'):.2f}; jit(vmap(exchange))/NumPy {q('kernel1', 'numpy'):.2f}, batch-first "
          f"{q('kernel1f', 'numpy'):.2f}; whole-batch/NumPy {q('whole', 'numpy'):.2f})")
    print(f"{'stream x*1.0+0 over in+out bytes':{w}} {res['stream']:14.4g}  {q('kernel64', 'stream'):8.2f}  "
          f"(kernel/streaming; {io_bytes / n:.0f} B/row in+out, {stream_bytes / tstream / 1e9:.2f} GB/s read+write"
          f" {2 * stream_bytes / tstream / 1e9:.2f}; sweep path/streaming {q('chunk', 'stream'):.2f}; "
          f"jit(vmap(exchange))/streaming {q('kernel1', 'stream'):.2f}, batch-first {q('kernel1f', 'stream'):.2f})")
    print(f"{'same, in place (donated: no new memory)':{w}} {res['stream_in_place']:14.4g}  "
          f"{q('kernel64out', 'stream_in_place'):8.2f}  (kernel out= / this: both without new memory; "
          f"kernel/this {q('kernel64', 'stream_in_place'):.2f}; jit(vmap(exchange)) batch-first/this "
          f"{q('kernel1f', 'stream_in_place'):.2f})")
    kf = lambda k: f"{statistics.median(u[1] for u in usage[k]):.0f}"  # noqa: E731
    print(f"page faults per call (medians): exchange_batch {kf('kernel64')}, out= {kf('kernel64out')}, "
          f"jit(vmap(exchange)) batch-first {kf('kernel1f')}, whole-batch {kf('whole')}, NumPy {kf('numpy')}, "
          f"streaming {kf('stream')}, in place {kf('stream_in_place')}; a result of this batch is "
          f"{nbytes(out) / 4096:.0f} pages of 4 KiB")
    by_round = ", ".join(f"{tn / tk:.2f} ({cpu * 1e9 / n:.0f} ns, {faults})" for tk, tn, (cpu, faults)
                         in zip(times["kernel1f"], times["numpy"], usage["kernel1f"]))
    print(f"jit(vmap(exchange)) batch-first / NumPy, round by round (its CPU time per row, page faults): {by_round}")
    for (name, layout), (tf, tg, gf, firstg, ok) in grads.items():
        label = f"gradient/forward, {name}, {layout}"
        versus = ""
        if layout == "exchange, batch-first":  # its gradient in chunks against the whole-batch gradient
            versus = (f"; whole-batch gradient (batch-first) / this gradient "
                      f"{ratio(gt, (name, layout, 'gradient'), (name, 'batch-first', 'gradient')):.2f}; this "
                      f"gradient / jit(vmap(exchange)) batch-first, every result "
                      f"{ratio(gt, ('every result',), (name, layout, 'gradient')):.2f}")
        if layout == "sum_over_rows, batch-first":  # the same loss, its gradient chunk by chunk
            via = (name, "exchange, batch-first")
            versus = (f"; the gradient through exchange / this gradient {ratio(gt, (name, layout, 'gradient'), via + ('gradient',)):.2f}"
                      f"; this gradient / the forward through exchange {ratio(gt, via + ('forward',), (name, layout, 'gradient')):.2f}")
        print(f"{label:{w}} {n / tg:14.4g}  {gf:8.2f}  (forward {n / tf:.4g}/s; grad finite: {ok}; "
              f"first call {firstg:.2f} s{versus})")
    print(f"first call (compile + run) exchange_batch float64: {first64:.2f} s (steady run {t64:.3f} s); "
          f"float32: {first32_s:.2f} s; jit(vmap(exchange)): {first1f:.2f} s batch-first")
    print(f"sweep {args.grid}x{args.grid} grid, {len(r.output_paths)} outputs + status: {tsw:.2f} s "
          f"({r.points / tsw:.3g} points/s; median of {len(sweeps)} calls, {tsw_range[0]:.2f}-{tsw_range[1]:.2f} s; "
          f"first call incl. compile {tsw_first:.2f} s)")
    if pc is None:
        print(pc_note)
    else:
        print(f"pycrash impc_calcs: {pc * 1e6:.1f} us per call ({1 / pc:.3g} exchanges/s; kernel is "
              f"{res['kernel64'] * pc:.0f}x) -- {pc_note}")
    print(f"statuses in the random batch: {dict((int(k), int(v)) for k, v in enumerate(statuses) if v)}")
    memory, sharded = [], None
    if args.memory_n:
        for keep in ("float32", "none"):
            memory.append(run_script("bench_sweep_memory.py", "--n", str(args.memory_n), "--keep", keep))
            print("sweep, peak memory (bench_sweep_memory.py): " + memory[-1])
    if args.sharded_n:
        sharded = run_script("bench_sweep_sharded.py", "--n", str(args.sharded_n),
                             XLA_FLAGS="--xla_force_host_platform_device_count=2")
        print("sweep, sharded (bench_sweep_sharded.py, XLA_FLAGS=--xla_force_host_platform_device_count=2): " + sharded)
    if args.naive_rows:
        print("naive baseline (bench_naive.py): "
              + run_script("bench_naive.py", "--rows", str(args.naive_rows), "--repeats", str(reps)))
    print_targets(q, grads, memory, sharded, (first64, first1f))


def print_targets(q, grads, memory, sharded, firsts):
    """Issue #5's numeric targets, each as this run measured it, and whether it holds in this run.
    (One run decides nothing where a ratio sits near its bound: RESULTS.md keeps the runs.)"""
    def verdict(value, bound, at_most=False):
        return f"{value:.2f} ({'met' if (value <= bound if at_most else value >= bound) else 'NOT met'})"

    print("\nissue #5 targets, this run:")
    print(f"  kernel / NumPy >= 10:          exchange_batch {verdict(q('kernel64', 'numpy'), 10)}; "
          f"jit(vmap(exchange)) batch-first {verdict(q('kernel1f', 'numpy'), 10)}")
    print(f"  kernel / streaming >= 0.3:     exchange_batch {verdict(q('kernel64', 'stream'), 0.3)}; "
          f"jit(vmap(exchange)) batch-first {verdict(q('kernel1f', 'stream'), 0.3)}")
    for name in ("delta-V", "residuals"):
        built = grads.get((name, "sum_over_rows, batch-first"))
        plain = grads.get((name, "exchange, batch-first"))
        print(f"  gradient / forward <= 3, {name + ':':10} "
              + (f"built by sum_over_rows {verdict(built[2], 3, at_most=True)}; " if built else "")
              + (f"written over jax.vmap(exchange) {verdict(plain[2], 3, at_most=True)}" if plain else ""))
    def compiles(layout):  # first calls of the two losses' gradients
        return ", ".join(f"{grads[(name, layout)][3]:.2f}" for name in ("delta-V", "residuals") if (name, layout) in grads)

    print(f"  first calls (compile + run):   exchange_batch {firsts[0]:.2f} s, jit(vmap(exchange)) {firsts[1]:.2f} s; "
          f"gradients by sum_over_rows {compiles('sum_over_rows, batch-first')} s, "
          f"over jax.vmap(exchange) {compiles('exchange, batch-first')} s")
    for line in memory:
        found = re.search(r"([0-9.e+]+) points, keep=(\w+): ([0-9.]+) s .*peak RSS ([0-9]+) MiB", line)
        if found:
            points, keep, seconds, mib = found.groups()
            print(f"  {points} points in < 2 GiB:      keep={keep}: peak RSS {mib} MiB in {seconds} s "
                  f"({'met' if int(mib) < 2048 else 'NOT met'})")
        else:
            print(f"  10^8 points in < 2 GiB:        not measured ({line})")
    if sharded is not None:
        found = re.search(r"largest difference ([0-9.e+-]+|nan), NaN in the same places: (\w+)", sharded)
        print("  sharded == one device:         " + (f"largest difference {found[1]}, NaN alike {found[2]}"
                                                     if found else f"not measured ({sharded})"))


def run_script(name, *argv, **env):
    """The last line a benchmark script beside this one prints, run in a process of its own (its
    peak memory is then its own, and XLA_FLAGS apply to it alone)."""
    import subprocess

    done = subprocess.run([sys.executable, str(Path(__file__).resolve().parent / name), *argv],
                          env=dict(os.environ, **env), capture_output=True, text=True)
    if done.returncode != 0:
        return f"failed (exit {done.returncode}): {done.stderr.strip().splitlines()[-1:]}"
    return done.stdout.strip().splitlines()[-1]


if __name__ == "__main__":
    main()
