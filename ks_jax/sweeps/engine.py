"""``sweep``: one case solved at every point of a grid or a list of samples of some of its inputs, in
chunks, with only the requested results kept (docs/sweeps.md)."""

from __future__ import annotations

import math
import operator
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from ..backend import Plan, checked_devices, plan_for, row_placement
from ..batch import CHUNK_ROWS
from ..batch.kernel import row_bytes
from ..batch.stages import run
from ..case import Case, as_arrays, automatic_part, canonical_path, check_output_path, defined_output, input_leaf
from ..case import follows_tow, input_kind, input_ties, on_fixed_object, set_input, undefined_kind, without_road
from ..case import with_times, without_approach, without_time
from ..case.errors import CaseError
from ..case.scale import move_scene, origin_offset, scene_origin, warn_far_from_origin, xy_index
from ..compilation import compiled, compiler_options
from ..limits import check_memory, is_float_dtype
from ..model.types import STATUS_TEXT, status_text
from ..progress import PROGRESS_DELAY, Progress
from ..solve import stages
from ..units import MAX_TURNS
from .columns import invalid_rows
from .result import SweepResult


def default_outputs(case) -> tuple:
    """The outputs a sweep keeps where none are asked for: the first exchange's impulse, energy loss and sliding,
    each vehicle's delta-V, PDOF and speed after it; with a road, each vehicle's rest position and yaw, and where the
    case has more than two bodies (so later exchanges of its own), each vehicle's cumulative delta-V and the total
    energy loss."""
    vehicles = range(case.vehicle_count)
    outputs = ("contact.impulse_magnitude", "contact.energy_loss", "contact.sliding",
               *(f"vehicles[{i}].{name}" for name in ("delta_v_magnitude", "pdof", "speed_after") for i in vehicles))
    if case.motion is not None:
        outputs += tuple(f"vehicles[{i}].{name}" for i in vehicles
                         for name in ("rest_position[0]", "rest_position[1]", "rest_yaw"))
    if case.vehicle_count + len(case.fixed) > 2:
        outputs += (*(f"vehicles[{i}].delta_v_cumulative_magnitude" for i in vehicles), "energy_loss_total")
    return outputs


DEFAULT_CHUNK = CHUNK_ROWS  # rows per device and chunk on a CPU (elsewhere: ``backend.Plan.rows``)
STATUS_CODES = tuple(sorted(STATUS_TEXT))  # the statuses counted on the device, in this order
# a sweep of at most this many points compiles quickly (``compilation.quick_jit``): its one short chunk runs in
# milliseconds, and compiling is most of its time; a larger one keeps XLA's defaults, where running counts
QUICK_POINTS = DEFAULT_CHUNK


def _row_inputs(base, paths, values, ties=()):
    """``base`` with ``values`` at ``paths``, and at each tied path (``case.input_ties``) the value of
    the path it follows."""
    inputs = base
    for p, v in zip(paths, values):
        inputs = set_input(inputs, p, v)
    for k, p in ties:
        inputs = set_input(inputs, p, values[k])
    return inputs


def _bucket(n):
    """A length rounded up to a power of two (at least 8): the length of the axes' value arrays and of a
    short sweep's one chunk in the compiled programs, so that a sweep of another size in the same bucket
    (41 speeds instead of 33, a 7 x 3 grid instead of 5 x 4) runs the programs already compiled."""
    return max(8, 1 << (max(int(n), 1) - 1).bit_length())


def _padded(values, dtype):
    """An axis' values padded to ``_bucket`` of its length with its last value (never read: a row's index
    on an axis is below the axis' size)."""
    values = np.asarray(values, dtype)
    fill = values[-1] if len(values) else 0.0
    return jnp.asarray(np.concatenate([values, np.full(_bucket(len(values)) - len(values), fill, dtype)]))


def _chunk_values(start, axes, mode, sizes, n_rows, total):
    """The swept values of rows start .. start + n_rows (clamped to the last point); ``sizes``: the
    axes' sizes, numbers or an array."""
    idx = start + jnp.arange(n_rows, dtype=start.dtype)
    idx = jnp.minimum(idx, total - 1)
    if mode == "zip":
        return [a[idx] for a in axes]
    out = []
    rest = idx
    for k in range(len(axes) - 1, -1, -1):  # row-major: the last axis varies fastest
        out.append(axes[k][rest % sizes[k]])
        rest = rest // sizes[k]
    return out[::-1]


@dataclass(frozen=True)
class ChunkProgram:
    """What the compiled program of one chunk of a sweep is made from: its cache key (``_program``).

    paths, ties: the swept input paths and the paths that follow them (``case.input_ties``); outputs: the
    results kept; mode: "grid" or "zip"; n_rows: the chunk's points; static_sizes: the axes' sizes compiled in
    (a sweep of several chunks: dividing by a constant is cheaper), or None: read at run time (a whole sweep in
    one chunk: a sweep of another size in the same ``_bucket`` runs the same program); auto_point, auto_normal,
    pole, motion, between: the case's pipeline (``solve.stages``); smoothing: tau of the smooth cone; out_dtype: the
    kept results' float dtype; devices: the rows are sharded over them; quick: compiled quickly
    (``QUICK_POINTS``); plan: the ``backend.Plan`` (the stages are fenced on the CPU's path only)."""

    paths: tuple
    ties: tuple
    outputs: tuple
    mode: str
    n_rows: int
    static_sizes: tuple | None
    auto_point: bool
    auto_normal: bool
    smoothing: float
    out_dtype: np.dtype
    devices: tuple
    quick: bool = False
    plan: Plan = Plan("cpu")
    pole: object = False
    motion: object = None
    between: tuple = (0, 1)


@lru_cache(maxsize=32)
def _program(key: ChunkProgram):
    """The jitted program of one chunk of ``key.n_rows`` points, sharded over ``key.devices`` along the rows.

    Called as ``(start, stop, axes, sizes, total, base)``: it makes each row's swept values from its flat
    index (grid: the index unravelled into one position per axis; zip: the k-th sample of every path),
    solves the rows through the case's pipeline (``solve.stages``, run by ``batch.stages.run``: each stage
    rebuilds the rows' inputs from ``base`` and the values, which costs less than storing them), and returns
    the requested outputs (NaN where undefined), the status, and, over the rows before ``stop``, the count
    of each status (``STATUS_CODES``, then any other) and of undefined values per output in
    ``undefined``: a sweep that keeps nothing then copies none of its rows to the host."""
    rows, replicated = row_placement(key.devices)
    pipeline = stages(key.auto_point, key.auto_normal, key.smoothing, key.pole, key.motion, key.between,
                      packed=key.plan.packed)
    undefined = tuple(p for p in key.outputs if undefined_kind(p))

    def chunk(start, stop, axes, sizes, total, base):
        vals = _chunk_values(start, axes, key.mode, sizes if key.static_sizes is None else key.static_sizes,
                             key.n_rows, total)
        vals = tuple(jax.lax.with_sharding_constraint(v, rows) for v in vals)

        def on_values(stage, last=False):
            def one(vals, *earlier):
                out = stage(_row_inputs(base, key.paths, vals, key.ties), *earlier)
                return _selected(out, key.outputs, key.out_dtype) if last else out
            one.block_rows = getattr(stage, "block_rows", 0)  # the motion to rest runs in blocks on a CPU
            return one

        out = run(tuple(on_values(f, k == len(pipeline) - 1) for k, f in enumerate(pipeline)), (vals,), plan=key.plan)
        counted = start + jnp.arange(key.n_rows, dtype=start.dtype) < stop
        status = out["status"].astype(jnp.int32)
        known = [jnp.sum(counted & (status == c), dtype=jnp.int32) for c in STATUS_CODES]
        solved = counted & ~invalid_rows(status)
        counts = {"status": jnp.stack(known + [jnp.sum(counted, dtype=jnp.int32) - sum(known)]),
                  "undefined": jnp.stack([jnp.sum(solved & jnp.isnan(out[p]), dtype=jnp.int32) for p in undefined]
                                         or [jnp.int32(0)])}
        return out, counts

    return jax.jit(chunk, in_shardings=(replicated,) * 6, out_shardings=(rows, replicated),
                   compiler_options=compiler_options(key.quick, key.devices[0].platform))


def _selected(result, outputs, out_dtype):
    """The requested outputs of a row's result (NaN where undefined: no stand-in number in a file), and its
    status as int8."""
    out = {}
    for p in outputs:
        x = defined_output(result, p)
        out[p] = x if x.dtype == jnp.bool_ else x.astype(out_dtype)
    out["status"] = result.contact.status.astype(jnp.int8)
    return out


def _whole_number(value, what):
    try:
        return operator.index(value)
    except TypeError:
        raise CaseError(f"{what} = {value!r}: must be a whole number") from None


def _check_values(path, values):
    if np.asarray(values).dtype == bool:
        raise CaseError(f"sweep over '{path}': the values are booleans (True, False); give numbers (SI)")
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise CaseError(f"sweep over '{path}': the values must be numbers (SI): {err}") from None
    if arr.ndim != 1 or arr.size == 0:
        raise CaseError(f"sweep over '{path}': give a non-empty 1-D list of values (SI), got shape {arr.shape}")
    if input_kind(path) == "angle":
        turns = np.abs(arr[np.isfinite(arr)]) / (2 * math.pi)
        if turns.size and turns.max() > MAX_TURNS:
            raise CaseError(f"sweep over '{path}': {turns.max():.3g} turns; an orientation this large has no meaning "
                            f"in floating point (at most {MAX_TURNS:g} turns): give angles within a turn")
    return arr


def sweep(case, over, outputs=None, mode="grid", chunk_size=None, smoothing=0.0, progress=None, devices=None,
          output_dtype=None, on_chunk=None, keep=True, index_range=None, plan=None) -> SweepResult:
    """Solve ``case`` at every point of a grid or a list of samples of some of its inputs.

    case: a ``Case`` (``ks_jax.load_case``). over: {input path: values}, values SI (m, kg, s,
    rad, rad/s), e.g. {"vehicles[1].speed": np.linspace(5, 30, 51), "contact.restitution": [0, .1]}.
    Any input path of ``ks_jax.case`` (``vehicles[i].mass``, ``.inertia[k]``, ``.position[k]``,
    ``.yaw``, ``.speed``, ``.course``, ``.yaw_rate``, ``contact.point[k]``, ``contact.normal``
    (azimuth), ``contact.restitution``, ``contact.friction``, ...).
    outputs: output paths of docs/model.md (components by index, e.g. ``vehicles[0].delta_v[0]``; one path may be a
    plain string); default ``default_outputs(case)``. ``"status"`` is always returned.
    mode: "grid" (cartesian product; result shape = (len(values) per path, in order)) or
    "zip" (samples of equal length n, e.g. Monte Carlo draws; result shape (n,)).
    chunk_size: rows per device and chunk (default 16384). smoothing: tau of the smooth cone.
    progress: None (a bar once a sweep of more than one chunk has run ``PROGRESS_DELAY`` = 2 s), True
    (from the start) or False; tqdm if installed, else a line on stderr.
    devices: the devices to shard every chunk over (default ``jax.local_devices()``, this process's).
    output_dtype: dtype of the stored float results, float32 or float64 (default: the compute dtype). In float32,
    a scene more than 1 km from the origin is solved about its CGs' midpoint (``case.scale.scene_origin``), and its
    ``contact.point[0]``/``[1]`` outputs are float64.
    on_chunk: called as ``on_chunk(lo, hi, chunk)`` with the flat index range and a dict of
    NumPy arrays (outputs and status) of every chunk, in order. keep: store the results (False:
    only status counts are kept; use with ``on_chunk`` for reductions of any size).
    index_range: (lo, hi) solve only these flat indices (row-major over the grid), e.g. one
    process's share of a multi-host sweep; the result is then flat, shape (hi - lo,).
    plan: how the rows are computed, a ``backend.Plan`` or its path ("cpu", "accelerator"); default, the path of
    ``devices``.
    """
    if on_chunk is not None and not callable(on_chunk):
        raise CaseError(f"sweep: on_chunk = {on_chunk!r}: must be a function, called as on_chunk(lo, hi, chunk) for "
                        "every chunk (or None)")
    request = check(case, over, outputs, mode, smoothing, index_range)
    return run_layout(layout(request, chunk_size, devices, output_dtype, plan), keep, on_chunk, progress)


@dataclass(frozen=True, eq=False)
class Request:
    """A sweep's arguments, checked (``check``): the case, its swept values by canonical path (``axes``, SI,
    float64), the outputs kept (canonical paths, ``"status"`` apart), the mode, the smoothing, the number of
    points of the whole sweep (``total``), the flat indices to solve (``lo`` .. ``hi``) and the result's shape
    (the sweep's, or flat where an index range was given)."""

    case: Case
    axes: dict
    outputs: tuple
    mode: str
    smoothing: float
    total: int
    lo: int
    hi: int
    shape: tuple


def check(case, over, outputs=None, mode="grid", smoothing=0.0, index_range=None) -> Request:
    """``sweep``'s arguments checked, each fault a ``CaseError`` naming it: the case, the swept paths and their
    values, the outputs, the mode, the smoothing and the index range."""
    if not isinstance(case, Case):
        raise CaseError(f"sweep needs a Case (ks_jax.load_case), got {type(case).__name__}")
    if not case.valid:
        raise CaseError(case.error)
    if mode not in ("grid", "zip"):
        raise CaseError(f"sweep mode = {mode!r}: mode must be 'grid' or 'zip'")
    axes = _checked_over(case, over)
    outputs = _checked_outputs(case, outputs, axes)
    if not 0.0 <= float(smoothing) < 1.0:
        raise CaseError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")
    shape = result_shape({p: len(a) for p, a in axes.items()}, mode)
    total = math.prod(shape)
    if total > np.iinfo(np.int64).max:
        raise CaseError(f"the sweep has {total:.3g} points, more than a 64-bit index counts "
                        f"({np.iinfo(np.int64).max:.3g}): sweep fewer values")
    lo, hi = _checked_range(index_range, total)
    return Request(case, axes, outputs, mode, float(smoothing), total, lo, hi,
                   shape if index_range is None else (hi - lo,))


def _checked_over(case, over):
    """{canonical path: values (float64)} of ``over``, each path an input the case lets a sweep vary."""
    if not isinstance(over, Mapping):
        raise CaseError(f"sweep over: give a mapping {{path: values}}, got {type(over).__name__}")
    if not over:
        raise CaseError("sweep needs at least one input path to vary: over={path: values}")
    for p in over:
        if not isinstance(p, str):
            raise CaseError(f"sweep over {p!r}: an input path is a string, e.g. 'vehicles[1].speed'")
    check_distinct(tuple(over), "sweep over")
    over = {canonical_path(p): v for p, v in over.items()}  # "vehicles[0]. yaw" is "vehicles[0].yaw"
    for p in over:
        name = automatic_part(case, p)  # raises PathError (a CaseError) naming a bad path
        if why := on_fixed_object(case, p) or without_road(case, p) or follows_tow(case, p):
            raise CaseError(f"sweep over {why}")
        if name:
            raise CaseError(f"sweep over '{p}': contact.{name} is automatic in this case (the file gives no "
                            f"contact.{name}), so it is computed, not an input; give contact.{name} in the case "
                            "to vary it")
    return {p: _check_values(p, v) for p, v in over.items()}


def _checked_outputs(case, outputs, axes):
    """The canonical output paths to keep (``"status"`` apart, always kept): ``outputs``, or the defaults."""
    if outputs is None:
        outputs = default_outputs(case)
    if not isinstance(outputs, (str, Iterable)) or isinstance(outputs, (bytes, Mapping)):
        raise CaseError(f"sweep: outputs = {outputs!r}: give output paths, a string or a list of strings (e.g. "
                        "['contact.impulse_magnitude', 'vehicles[0].delta_v_magnitude']), or None (the defaults)")
    outputs = tuple([outputs] if isinstance(outputs, str) else outputs)
    for p in outputs:
        if not isinstance(p, str):
            raise CaseError(f"output {p!r}: an output path is a string, e.g. 'contact.impulse_magnitude'")
        if p != "status":
            check_output_path(p)
            if why := on_fixed_object(case, p) or without_road(case, p) or without_approach(case, p) \
                    or without_time(case, p):
                raise CaseError(f"output {why}")
    outputs = tuple(dict.fromkeys(canonical_path(p) for p in outputs if canonical_path(p) != "status"))
    for p in outputs:
        if p in axes:
            raise CaseError(f"output '{p}' is also a swept input: its values are the input's column already "
                            "(leave it out of the outputs)")
    if "contact.time" in outputs and not (case.auto_point or case.auto_normal):
        raise CaseError("output 'contact.time' is the first-contact time of automatic contact (docs/model.md); "
                        "this case gives contact.point and contact.normal, so its exchange is at the case state "
                        "(leave contact.time out)")
    return outputs


def _checked_range(index_range, total):
    """(lo, hi): the flat indices to solve, all of them by default."""
    if index_range is None:
        return 0, total
    if isinstance(index_range, (str, bytes)) or not hasattr(index_range, "__len__") or len(index_range) != 2:
        raise CaseError(f"index_range = {index_range!r}: give two whole numbers (lo, hi)")
    try:
        lo, hi = (operator.index(v) for v in index_range)
    except TypeError:
        raise CaseError(f"index_range = {tuple(index_range)}: lo and hi must be whole numbers") from None
    if not 0 <= lo <= hi <= total:
        raise CaseError(f"index_range = {index_range}: must satisfy 0 <= lo <= hi <= {total}")
    return lo, hi


@dataclass(frozen=True, eq=False)
class Layout:
    """How a checked sweep (``request``) runs: its chunk's program (``program``, the key of ``_program``), the
    scene's inputs as arrays (``base``, moved about the CGs' midpoint in float32 far from the origin), the
    swept values as the program reads them (``axes``: padded to their ``_bucket`` in a sweep of one chunk) and
    the axes' sizes, the offsets added back to moved outputs (``moved``: path -> metres), and the index dtype."""

    request: Request
    program: ChunkProgram
    base: object
    axes: tuple
    sizes: object
    moved: dict
    index_dtype: object


def _check_output_dtype(output_dtype):
    """Results are stored as float32 or float64: an integer or boolean type would turn an invalid row's NaN into a
    number that reads as a result, float16 would overflow a valid one to inf."""
    if not (output_dtype is None or is_float_dtype(output_dtype)):
        raise CaseError(f"sweep: output_dtype = {output_dtype!r}: must be float32 or float64 (or None, the compute "
                        "dtype)")


def layout(request: Request, chunk_size=None, devices=None, output_dtype=None, plan=None) -> Layout:
    """The ``Layout`` of ``request``: rows per chunk (``chunk_size`` per device, default the plan's,
    ``backend.Plan.rows``; a small sweep is one chunk rounded up to its ``_bucket``), where the scene is solved,
    and its program. ``plan``: a ``backend.Plan`` or its path; default, the path of ``devices``."""
    case, n_points = request.case, request.hi - request.lo
    _check_output_dtype(output_dtype)
    devices = checked_devices(devices, "sweep")
    plan = plan_for(plan, devices)
    if chunk_size is None:  # rows of the case's inputs and as many result bytes (``backend.Plan.rows``)
        one_row = jax.tree_util.tree_map(lambda x: np.asarray(x)[None], as_arrays(case.inputs))
        per_device = plan.rows(2 * row_bytes(one_row), devices[0])
    else:
        per_device = _whole_number(chunk_size, "chunk_size")
    if per_device <= 0:
        raise CaseError(f"chunk_size = {chunk_size}: must be positive")
    # small sweeps: one short chunk, of a length rounded up (``_bucket``) so that other sizes reuse its programs
    n_rows = min(per_device * len(devices), _bucket(-(-max(n_points, 1) // len(devices))) * len(devices))

    # float32 far from the origin: the scene, swept positions included, is solved about the CGs' midpoint
    # (case.scale.scene_origin), and contact.point outputs are moved back, in float64
    paths = tuple(request.axes)
    origin = scene_origin(case.inputs, [v for p, v in request.axes.items() if xy_index(p) is not None])
    moved = {} if origin is None else {p: origin_offset(p, origin) for p in (*paths, *request.outputs)}
    moved = {p: float(off) for p, off in moved.items() if off is not None}
    inputs = case.inputs if origin is None else move_scene(case.inputs, origin, case.auto_point)
    swept = {p: a - moved.get(p, 0.0) for p, a in request.axes.items()}
    warn_far_from_origin(inputs, [v for p, v in swept.items() if p in moved], what="the swept scene",
                         about="the origin" if origin is None else "its CGs' midpoint", auto_point=case.auto_point)
    dtype = jnp.result_type(float)
    index_dtype = jnp.int64 if jax.config.jax_enable_x64 else jnp.int32
    if request.total > np.iinfo(np.int32).max and index_dtype == jnp.int32:
        raise CaseError(f"{request.total} points need 64-bit indices: enable jax_enable_x64")
    # a whole sweep in one chunk: its axes padded and its sizes an argument, for any size in the same buckets;
    # a larger one (or a range of one) keeps its exact axes (a zip of 10^8 samples is not padded) and sizes
    one_chunk = request.total <= n_rows
    sizes = tuple(len(a) for a in request.axes.values())
    program = ChunkProgram(paths, input_ties(case, paths), request.outputs, request.mode, n_rows,
                           None if one_chunk else sizes, case.auto_point, case.auto_normal, request.smoothing,
                           np.dtype(output_dtype or dtype), devices,
                           n_points <= QUICK_POINTS, plan,
                           case.pole, with_times(case.motion, request.outputs), case.between)
    axes = tuple(_padded(a, dtype) if one_chunk else jnp.asarray(a, dtype=dtype) for a in swept.values())
    return Layout(request, program, as_arrays(inputs), axes, jnp.asarray(sizes, dtype=index_dtype), moved, index_dtype)


def run_layout(layout: Layout, keep=True, on_chunk=None, progress=None) -> SweepResult:
    """Solve ``layout``'s points chunk by chunk, each dispatched while the previous one's results are collected:
    kept (``keep``) and handed to ``on_chunk``, the statuses and undefined results counted."""
    request, key = layout.request, layout.program
    lo, hi, n_points = request.lo, request.hi, request.hi - request.lo
    store = _store(request, key.out_dtype, layout.moved) if keep else {}
    counts = np.zeros(len(STATUS_CODES) + 1, dtype=np.int64)
    undefined = {p: 0 for p in request.outputs if undefined_kind(p)}
    rows_wanted = keep or on_chunk is not None  # else only the counts leave the device

    def index(i):
        return jnp.asarray(i, dtype=layout.index_dtype)

    stop, total = index(hi), index(request.total)
    show = n_points > key.n_rows if progress is None else bool(progress)  # one chunk: one step, nothing to show
    bar = Progress(n_points, "ks-jax sweep", "pt", show, PROGRESS_DELAY if progress is None else 0.0)
    # compiled before the clock starts: a sweep's seconds and rate count solving, its compile is said apart
    t0 = time.perf_counter()
    executable = compiled(_program(key), index(lo), stop, layout.axes, layout.sizes, total, layout.base)
    compile_seconds = time.perf_counter() - t0
    t0 = time.perf_counter()

    def launch(start):
        out, tally = executable(index(start), stop, layout.axes, layout.sizes, total, layout.base)
        if rows_wanted and not key.plan.cpu:  # start the copy to the host now: it runs while the next chunk computes
            for x in out.values():
                x.copy_to_host_async()
        return start, out, tally

    def collect(item):
        start, out, tally = item
        n = min(key.n_rows, hi - start)
        counts[:] += np.asarray(tally["status"])
        for p, k in zip(undefined, np.asarray(tally["undefined"])):
            undefined[p] += int(k)
        if rows_wanted:
            chunk = {k: np.asarray(out[k])[:n] for k in (*request.outputs, "status")}  # in the order asked
            for p in request.outputs:
                if p in layout.moved:
                    chunk[p] = chunk[p].astype(np.float64) + layout.moved[p]
            for k, v in chunk.items() if keep else ():
                store[k][start - lo:start - lo + n] = v
            if on_chunk is not None:
                on_chunk(start, start + n, chunk)
        bar.update(n)

    try:
        pending = None
        for start in range(lo, hi, key.n_rows):
            item = launch(start)  # dispatched asynchronously: overlaps the previous transfer
            if pending is not None:
                collect(pending)
            pending = item
        if pending is not None:
            collect(pending)
    finally:
        bar.close()
    seconds = time.perf_counter() - t0
    return _result(request, store, counts, undefined, seconds, compile_seconds)


def _store(request: Request, out_dtype, moved):
    """The arrays a kept sweep's results are written into (flat), its memory checked first."""
    n_points, outputs = request.hi - request.lo, request.outputs
    itemsize = sum(1 if p.endswith(".sliding") else 8 if p in moved else out_dtype.itemsize for p in outputs)
    check_memory(n_points * (itemsize + 1), f"keeping {n_points} points of {len(outputs)} outputs",
                  "pass keep=False and on_chunk (ks-jax sweep --out writes chunk by chunk), index_range, "
                  "output_dtype=np.float32 or fewer outputs")
    store = {p: np.empty(n_points, dtype=bool if p.endswith(".sliding") else np.float64 if p in moved else out_dtype)
             for p in outputs}
    store["status"] = np.empty(n_points, dtype=np.int8)
    return store


def _result(request, store, counts, undefined, seconds, compile_seconds):
    """The ``SweepResult`` of a run: the kept arrays in the result's shape, and the statuses counted."""
    status_counts = {status_text(c): int(k) for c, k in zip(STATUS_CODES, counts) if k}
    if counts[-1]:
        status_counts["invalid: unknown status"] = int(counts[-1])
    return SweepResult({k: v.reshape(request.shape) for k, v in store.items()}, request.axes, request.shape,
                       request.mode,
                       request.hi - request.lo, status_counts, seconds, (request.lo, request.hi), request.outputs,
                       undefined=undefined, compile_seconds=compile_seconds, names=tuple(request.case.vehicle_names))


def check_distinct(paths, what):
    """Refuse two paths that name one input ("vehicles[0].yaw_rate" is "vehicles[0].angular_velocity[2]";
    spaces do not count): the later would override the earlier, under the earlier's name."""
    seen = {}
    for p in paths:
        group, vi, name, idx = input_leaf(p)
        key = (group, vi, name, tuple(sorted(idx)) if name == "inertia" else idx)  # [0][1] is [1][0]
        if key in seen:
            same = "twice" if seen[key] == p else f"and '{seen[key]}'"
            raise CaseError(f"{what} '{p}' {same}: both name the same input, so one would override the other; "
                            "give it once")
        seen[key] = p


def result_shape(sizes, mode):
    """A sweep's result shape from {path: number of values}: one axis per path ("grid") or one axis
    ("zip", which needs the same number for every path)."""
    counts = tuple(sizes.values())
    if mode != "zip":
        return counts
    if len(set(counts)) != 1:
        raise CaseError("sweep mode 'zip' needs the same number of values for every path, got "
                        + ", ".join(f"{p}: {n}" for p, n in sizes.items()))
    return counts[:1]
