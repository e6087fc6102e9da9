"""Sweeps at scale: one case, many values of some inputs (a grid or samples), chosen results.

``sweep(case, over={path: values}, outputs=[path, ...], mode="grid"|"zip")`` solves the case
at every point and returns a ``SweepResult`` (a mapping output path -> NumPy array shaped like
the grid, with ``"status"`` always included).

How it scales
-------------
- Nothing of size "number of points" is built on the device. The points are taken in chunks of
  ``chunk_size`` consecutive flat indices; inside one jitted call per chunk each row's inputs
  are made from its index (grid: the index is unravelled into one position per axis; zip: the
  index picks the k-th sample of every path) and only the requested outputs leave the device.
- The host keeps one array per requested output (plus ``status`` as int8), so memory is
  ``points x (sum of output itemsizes + 1)`` bytes: 10^8 points x one float32 output is about
  0.5 GB; x k float64 outputs 8e8 k bytes. For more, pass ``on_chunk`` (a callback that gets
  every chunk's outputs: reduce or stream them to disk) with ``keep=False``: memory then stays
  at a few chunks whatever the number of points (``ResultWriter`` streams every chunk to a
  .csv, .npz or .parquet file that way; ``ks-jax sweep`` uses it). ``output_dtype=np.float32``
  halves the stored results (the computation stays in the case's float type).
- Invalid rows (e.g. a restitution above 1) get their status code (``ks_jax.status_text``)
  and NaN results; the other rows are solved as usual.
- An explicit-contact chunk is solved in three jitted calls whose outputs are stored once per
  row: the status and the sines/cosines of both vehicles' angles (``exchange.prepare``), the
  impulse and what the results derive from (``exchange.impulse_stage``), then the results
  (``exchange.results_stage``). In one program XLA's CPU loop fusion re-evaluates shared values
  (the ~100 input checks, the scalar float64 sines/cosines, the 3x3 algebra) in every loop that
  reads them: the three calls take half the time per row (benchmarks/RESULTS.md). An
  automatic-contact chunk is solved in three calls too: the status (``exchange.input_status``),
  the contact (``geometry.automatic_stage``: first contact, free motion, overlap) and the
  exchange there (``geometry.exchange_at_contact``); a third of the time per row where no
  vehicle turns.

Devices
-------
Every chunk is split over ``devices`` (default ``jax.devices()``): a 1-D ``jax.sharding.Mesh``
named ``"batch"``, the chunk's row axis sharded over it with ``NamedSharding`` (the chunk is
padded to a multiple of the device count; padded rows are dropped). The same code runs on one
CPU, on ``XLA_FLAGS=--xla_force_host_platform_device_count=N`` host devices, or on GPUs.

Several hosts (``jax.distributed``)
-----------------------------------
Two ways, see docs/sweeps.md:
1. Independent slices (simplest, no communication): every process calls
   ``jax.distributed.initialize()`` (or nothing at all) and
   ``sweep(..., index_range=(lo, hi), devices=jax.local_devices())`` with its own slice of the
   flat index range ``[0, result.points)``, e.g. ``lo, hi = np.array_split(range(n), P)[i]``
   bounds for process ``i = jax.process_index()`` of ``P = jax.process_count()``; each writes
   its file, or they are gathered afterwards.
2. One global mesh: after ``jax.distributed.initialize()``, ``jax.devices()`` lists the devices
   of all processes and ``sweep(..., devices=jax.devices())`` shards every chunk over all of
   them; every process runs the same call, and each gets (and keeps) the whole result, which
   JAX gathers across hosts.
"""

from __future__ import annotations

import math
import operator
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import units as U
from .case import UNDEFINED_REASONS, Case, CaseError, _input_leaf, as_arrays, check_output_path, defined_output
from .case import automatic_part, canonical_path, input_ties, input_kind, move_scene, origin_offset, output_kind
from .case import scene_origin, set_input, speed_status, to_pytrees, undefined_kind, warn_far_from_origin, xy_index
from .exchange import CHUNK_ROWS
from .quick import QUICK_CPU
from .stored import stored_jit
from .types import INVALID_NONFINITE, STATUS_TEXT, status_text

DEFAULT_OUTPUTS = (
    "contact.impulse_magnitude",
    "contact.energy_loss",
    "contact.sliding",
    "vehicles[0].delta_v_magnitude",
    "vehicles[1].delta_v_magnitude",
    "vehicles[0].pdof",
    "vehicles[1].pdof",
    "vehicles[0].speed_after",
    "vehicles[1].speed_after",
)
# rows per device and chunk, as in exchange's vmap rule: cache-resident (1.4-2x faster than 1 << 16 here)
DEFAULT_CHUNK = CHUNK_ROWS
# A sweep of at most this many points compiles its programs with XLA's quicker CPU settings (``ks_jax.quick``):
# a 41 x 7 grid of the seed chapter from the command line took 3.1-3.3 s against 5.6-6.2 s, of the automatic
# T-bone 5.4-5.7 s against 10.2 s. Compiled that way the programs run slower (3.5 against 0.35 us per point for explicit contact,
# 19-22 against 7.3 for automatic), so a larger sweep keeps XLA's defaults (benchmarks/RESULTS.md, 2026-11-26).
QUICK_POINTS = DEFAULT_CHUNK
PROGRESS_DELAY = 2.0  # s: with progress=None a sweep that runs longer than this shows a bar


@dataclass
class SweepResult(Mapping):
    """Results of a sweep: a mapping output path -> array (grid shape, or (n,) for zip and
    index ranges), ``"status"`` (int8 codes, ``ks_jax.status_text``) always among them.

    axes: path -> the values (SI) swept along each grid axis (zip: the samples).
    shape: the result shape. mode: "grid" or "zip". points: number of points solved.
    status_counts: status text -> number of points. seconds: wall time of the sweep.
    undefined: output path -> the number of solved points (status not "invalid") where it is NaN
    because MODEL.md leaves it undefined there (``case.defined_output``: a PDOF or impulse direction
    without an impulse, the time of a contact that never happens, EES without crush); ``summary`` says why.
    index_range: the flat indices solved (all of them unless ``index_range`` was given).
    strides: () for every point solved; (k0, k1, ...) for a thinned copy that holds every k-th
    value along each axis (``thinned``, ``SweepSample``: what a picture needs of a large sweep).
    """

    outputs: dict
    axes: dict
    shape: tuple
    mode: str
    points: int
    status_counts: dict
    seconds: float
    index_range: tuple = (0, 0)
    output_paths: tuple = field(default=())
    strides: tuple = ()
    undefined: dict = field(default_factory=dict)

    def __getitem__(self, key):
        return self.outputs[key]

    def __iter__(self):
        return iter(self.outputs)

    def __len__(self):
        return len(self.outputs)

    def inputs(self):
        """path -> the input value (SI) at every point, flat (in the order of the outputs)."""
        return _grid_inputs(self.axes, self.mode, *self.index_range)

    def table(self, units="si"):
        """Flat columns (one row per point): the inputs, the outputs, the status code and its text, as a
        .csv of ``write_results`` holds them (``pandas.DataFrame(result.table())`` makes a data frame): a
        flag (``contact.sliding``) of an invalid row is None (an object column where there is one).
        units: "si", or "us" (mph, ft, lbf s, ft lbf, deg, deg/s, lb; the unit in each name)."""
        _check_units(units, "units")
        check_kept(self)
        cols = _columns(_axes_in_units(self.axes, units), self.mode, *self.index_range,
                        _outputs_in_units(self.outputs, units))
        cols["status_text"] = _status_texts(cols["status"])
        return _missing_flags(cols)

    def thinned(self, limit=None):
        """This result with at most ``limit`` values along each axis (default: ``PLOT_LIMITS``,
        by the number of axes): every k-th value, from the first, of the axes and of every output
        (a view, no copy). Needs a kept result of a whole grid or of all the samples."""
        _check_whole(self)
        strides = plot_strides(self.shape, self.mode, limit)
        cut = tuple(slice(None, None, k) for k in strides)
        return _thinned(self, {p: v[cut] for p, v in self.outputs.items()}, strides)

    def summary(self) -> str:
        counts = ", ".join(f"{k}: {v}" for k, v in self.status_counts.items())
        rate = self.points / self.seconds if self.seconds > 0 else float("inf")
        text = (f"{self.points} points ({self.mode}, shape {self.shape}) in {self.seconds:.3g} s "
                f"({rate:.3g} points/s); status: {counts}")
        return text + "".join(f"\n  undefined (NaN) at {n} solved point{'s' * (n != 1)}: {p}, where "
                              f"{UNDEFINED_REASONS[undefined_kind(p)]}" for p, n in self.undefined.items() if n)


# at most this many values per axis of what a picture of a sweep shows (1 or 2 grid axes; zip: samples)
PLOT_LIMITS = {1: 100_000, 2: 1000}
PLOT_SAMPLES = 1_000_000


def plot_strides(shape, mode, limit=None):
    """Every k-th value along each axis of a result of ``shape`` keeps at most ``limit`` values per
    axis (default: ``PLOT_LIMITS`` for a grid, ``PLOT_SAMPLES`` for zip samples)."""
    if limit is None:
        limit = PLOT_SAMPLES if mode == "zip" else PLOT_LIMITS.get(len(shape), 1000)
    if int(limit) < 1:
        raise CaseError(f"limit = {limit}: must be at least 1 value per axis")
    return tuple(max(1, -(-int(n) // int(limit))) for n in shape)


def check_kept(result):
    """Raise unless ``result`` kept its results (a picture or ``thinned`` needs them)."""
    if not result.outputs:
        raise CaseError("this sweep kept no results (keep=False): sweep again with keep=True, or collect a "
                        "ks_jax.sweeps.SweepSample in on_chunk and draw its result")


def _check_whole(result):
    check_kept(result)
    sizes = tuple(len(v) for v in result.axes.values())
    shape = sizes[:1] if result.mode == "zip" else sizes
    whole = result.shape == shape and tuple(result.index_range) == (0, math.prod(shape))
    if not whole or result.strides:
        raise CaseError(f"this result holds points {result.index_range[0]}..{result.index_range[1] - 1} of a sweep "
                        f"or is thinned already (strides {result.strides}): thin a whole sweep")


def _thinned(result, outputs, strides):
    """``result`` holding ``outputs`` (every k-th value of a whole sweep's, k = ``strides``) and its axes
    cut the same way."""
    axes = {p: np.asarray(v)[::strides[0 if result.mode == "zip" else i]]
            for i, (p, v) in enumerate(result.axes.items())}
    shape = outputs["status"].shape
    n = math.prod(shape)
    return replace(result, outputs=outputs, axes=axes, shape=shape, points=n, index_range=(0, n), strides=strides)


class SweepSample:
    """Collects, as ``sweep`` streams its chunks (``on_chunk``), every k-th value along each axis
    (``plot_strides``): a small kept result of a sweep of any size, for a picture. ``result(sweep_result)``
    returns it as a ``SweepResult`` with ``strides`` set. Memory: the thinned points only."""

    def __init__(self, axes, mode, shape, limit=None):
        self.axes, self.mode, self.shape = dict(axes), mode, tuple(int(n) for n in shape)
        self.strides = plot_strides(self.shape, mode, limit)
        self.thin_shape = tuple(-(-n // k) for n, k in zip(self.shape, self.strides))
        self.store = {}

    def chunk(self, lo, hi, chunk):
        inner = math.prod(self.shape[1:])
        first, last, k = lo // inner, (hi - 1) // inner, self.strides[0]
        if -(-first // k) * k > last:  # no kept value of the first axis in this chunk
            return
        idx = np.arange(lo, hi)
        pos = np.unravel_index(idx, self.shape)
        keep = np.ones(idx.shape, bool)
        for p, k in zip(pos, self.strides):
            keep &= p % k == 0
        target = np.ravel_multi_index(tuple(p[keep] // k for p, k in zip(pos, self.strides)), self.thin_shape)
        for name, v in chunk.items():
            if name not in self.store:
                self.store[name] = np.zeros(math.prod(self.thin_shape), v.dtype)
            self.store[name][target] = v[keep]

    def result(self, swept: SweepResult) -> SweepResult:
        """The thinned result of ``swept`` (the ``keep=False`` result of the same sweep)."""
        if swept.index_range != (0, math.prod(self.shape)):
            raise CaseError(f"a SweepSample needs the whole sweep; it got points {swept.index_range}")
        outputs = {p: v.reshape(self.thin_shape) for p, v in self.store.items()}
        return _thinned(replace(swept, axes=self.axes), outputs, self.strides)


# ---------------------------------------------------------------------------------------
# the jitted chunk


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


@lru_cache(maxsize=32)
def _compiled(paths, ties, outputs, mode, n_rows, static_sizes, auto_point, auto_normal, smoothing, out_dtype, devices,
              quick=False):
    """(status_fn, impulse_fn, solve_fn): jitted, sharded over ``devices`` along the row axis; ``quick``:
    compiled with ``ks_jax.quick.QUICK_CPU`` (``QUICK_POINTS``); ``static_sizes``: the axes' sizes compiled in
    (a sweep of several chunks: dividing by a constant is cheaper), or None: read from the ``sizes`` argument
    (a whole sweep in one chunk: a sweep of another size in the same ``_bucket`` runs the same programs).

    Three calls per chunk for an explicit contact: the status and angle sines/cosines
    (``exchange.prepare``), the impulse (``exchange.impulse_stage``), then the results
    (``exchange.results_stage``). Each call's outputs are stored once per row; in one program
    XLA's CPU fusion would re-derive them inside every loop that reads them (2x slower here).
    The first call also returns the chunk's swept values, which the other two read, and adds a
    negative speed to the status (``case.speed_status``). For automatic contact the three are
    ``solve.auto_status``, ``solve.auto_contact`` and ``solve.auto_exchange`` (the speed status
    added last, as ``solve.solve_inputs`` does).
    """
    from .exchange import impulse_stage, prepare, results_stage
    from .solve import auto_contact, auto_exchange, auto_status

    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    rows = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))
    replicated = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
    split = auto_point or auto_normal  # automatic contact: status, contact, exchange

    def values(start, axes, sizes, total):
        vals = _chunk_values(start, axes, mode, sizes if static_sizes is None else static_sizes, n_rows, total)
        return [jax.lax.with_sharding_constraint(v, rows) for v in vals]

    def status_fn(start, axes, sizes, total, base):  # the chunk's swept values, made once, and their status
        vals = values(start, axes, sizes, total)
        if split:
            return vals, (jax.vmap(lambda *v: auto_status(_row_inputs(base, paths, v, ties)))(*vals), None)

        def one(*v):
            inputs = _row_inputs(base, paths, v, ties)
            status, trig = prepare(*to_pytrees(inputs))
            return speed_status(inputs, status), trig

        return vals, jax.vmap(one)(*vals)

    def impulse_fn(base, vals, prepared):
        status, trig = prepared
        if split:
            return jax.vmap(lambda st, *v: auto_contact(_row_inputs(base, paths, v, ties), st, auto_point,
                                                        auto_normal))(status, *vals)
        return jax.vmap(lambda st, tr, *v: impulse_stage(*to_pytrees(_row_inputs(base, paths, v, ties)), smoothing,
                                                         st, tr, for_gradients=False))(status, trig, *vals)

    def solve_fn(base, vals, prepared, stage):
        status, _ = prepared

        def one(st, stg, *v):
            inputs = _row_inputs(base, paths, v, ties)
            if split:
                res = auto_exchange(inputs, st, stg, smoothing)
            else:
                res = results_stage(*to_pytrees(inputs), st, stg)
            out = {}
            for p in outputs:
                x = defined_output(res, p)  # NaN where undefined: no stand-in number in a file
                out[p] = x if x.dtype == jnp.bool_ else x.astype(out_dtype)
            out["status"] = res.contact.status.astype(jnp.int8)
            return out

        return jax.vmap(one, in_axes=(0, None if stage is None else 0) + (0,) * len(vals))(status, stage, *vals)

    options = QUICK_CPU if quick else None
    # what the three close over, for the key of the programs the command line keeps (``ks_jax.stored``)
    context = (paths, ties, outputs, mode, n_rows, static_sizes, auto_point, auto_normal, smoothing,
               jnp.dtype(out_dtype).name, len(devices))
    status_jit = stored_jit(status_fn, context, in_shardings=(replicated,) * 5,
                            out_shardings=rows, compiler_options=options)
    impulse_jit = stored_jit(impulse_fn, context, in_shardings=(replicated, rows, rows), out_shardings=rows,
                             compiler_options=options)
    solve_jit = stored_jit(solve_fn, context, in_shardings=(replicated, rows, rows, rows), out_shardings=rows,
                           compiler_options=options)
    return status_jit, impulse_jit, solve_jit


# ---------------------------------------------------------------------------------------
# progress


class _Progress:
    """A bar on stderr (tqdm if installed, else a line) that appears once ``delay`` seconds have gone
    by, so that only long sweeps show one."""

    def __init__(self, total, enabled, delay=0.0):
        self.total, self.enabled, self.done, self.delay = total, enabled, 0, delay
        self.bar = None
        self.t0 = time.perf_counter()
        self.last = 0.0
        if enabled:
            try:
                from tqdm.auto import tqdm

                self.bar = tqdm(total=total, unit="pt", unit_scale=True, desc="ks-jax sweep", file=sys.stderr,
                                delay=delay)
            except ImportError:
                self.bar = None

    def update(self, n):
        self.done += n
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(n)
            return
        now = time.perf_counter()
        if now - self.t0 < self.delay:
            return
        if now - self.last > 1.0 or self.done >= self.total:
            self.last = now
            rate = self.done / max(now - self.t0, 1e-9)
            print(f"\rks-jax sweep: {self.done}/{self.total} points ({100 * self.done / self.total:.0f}%, "
                  f"{rate:.3g}/s)", end="" if self.done < self.total else "\n", file=sys.stderr, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()


# ---------------------------------------------------------------------------------------
# the sweep


def _memory_bytes():
    """This machine's physical memory in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def _check_memory(nbytes, what, advice):
    """CaseError where ``what`` needs more bytes than the machine has (before numpy's MemoryError)."""
    memory = _memory_bytes()
    if memory is not None and nbytes > memory:
        raise CaseError(f"{what} needs {nbytes / 2**30:.3g} GiB, more than this machine's {memory / 2**30:.3g} GiB: "
                        f"{advice}")


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
    return arr


def sweep(case, over, outputs=None, mode="grid", chunk_size=None, smoothing=0.0, progress=None, devices=None,
          output_dtype=None, on_chunk=None, keep=True, index_range=None) -> SweepResult:
    """Solve ``case`` at every point of a grid or a list of samples of some of its inputs.

    case: a ``Case`` (``ks_jax.load_case``). over: {input path: values}, values SI (m, kg, s,
    rad, rad/s), e.g. {"vehicles[1].speed": np.linspace(5, 30, 51), "contact.restitution": [0, .1]}.
    Any input path of ``ks_jax.case`` (``vehicles[i].mass``, ``.inertia[k]``, ``.position[k]``,
    ``.yaw``, ``.speed``, ``.course``, ``.yaw_rate``, ``contact.point[k]``, ``contact.normal``
    (azimuth), ``contact.restitution``, ``contact.friction``, ...).
    outputs: output paths of MODEL.md section 4 (components by index, e.g.
    ``vehicles[0].delta_v[0]``; one path may be a plain string); default ``DEFAULT_OUTPUTS``. ``"status"`` is always returned.
    mode: "grid" (cartesian product; result shape = (len(values) per path, in order)) or
    "zip" (samples of equal length n, e.g. Monte Carlo draws; result shape (n,)).
    chunk_size: rows per device and chunk (default 16384). smoothing: tau of the smooth cone.
    progress: None (a bar once a sweep of more than one chunk has run ``PROGRESS_DELAY`` = 2 s), True
    (from the start) or False; tqdm if installed, else a line on stderr.
    devices: the devices to shard every chunk over (default ``jax.devices()``).
    output_dtype: dtype of the stored float results (default: the compute dtype). In float32, a scene
    more than 1 km from the origin is solved about its CGs' midpoint (``case.scene_origin``), and its
    ``contact.point[0]``/``[1]`` outputs are float64.
    on_chunk: called as ``on_chunk(lo, hi, chunk)`` with the flat index range and a dict of
    NumPy arrays (outputs and status) of every chunk, in order. keep: store the results (False:
    only status counts are kept; use with ``on_chunk`` for reductions of any size).
    index_range: (lo, hi) solve only these flat indices (row-major over the grid), e.g. one
    process's share of a multi-host sweep; the result is then flat, shape (hi - lo,).
    """
    if not isinstance(case, Case):
        raise CaseError(f"sweep needs a Case (ks_jax.load_case), got {type(case).__name__}")
    if not case.valid:
        raise CaseError(case.error)
    if mode not in ("grid", "zip"):
        raise CaseError(f"sweep mode = {mode!r}: mode must be 'grid' or 'zip'")
    if not isinstance(over, Mapping):
        raise CaseError(f"sweep over: give a mapping {{path: values}}, got {type(over).__name__}")
    if not over:
        raise CaseError("sweep needs at least one input path to vary: over={path: values}")
    for p in over:
        if not isinstance(p, str):
            raise CaseError(f"sweep over {p!r}: an input path is a string, e.g. 'vehicles[1].speed'")
    _check_distinct(tuple(over), "sweep over")
    over = {canonical_path(p): v for p, v in over.items()}  # "vehicles[0]. yaw" is "vehicles[0].yaw"
    paths = tuple(over)
    for p in paths:
        name = automatic_part(case, p)  # raises PathError (a CaseError) naming a bad path
        if name:
            raise CaseError(f"sweep over '{p}': contact.{name} is automatic in this case (the file gives no "
                            f"contact.{name}), so it is computed, not an input; give contact.{name} in the case "
                            "to vary it")
    axes = {p: _check_values(p, over[p]) for p in paths}
    outputs = tuple(DEFAULT_OUTPUTS if outputs is None else [outputs] if isinstance(outputs, str) else outputs)
    for p in outputs:
        if not isinstance(p, str):
            raise CaseError(f"output {p!r}: an output path is a string, e.g. 'contact.impulse_magnitude'")
        if p != "status":
            check_output_path(p)
    outputs = tuple(dict.fromkeys(canonical_path(p) for p in outputs if canonical_path(p) != "status"))
    for p in outputs:
        if p in axes:
            raise CaseError(f"output '{p}' is also a swept input: its values are the input's column already "
                            "(leave it out of the outputs)")
    if "contact.time" in outputs and not (case.auto_point or case.auto_normal):
        raise CaseError("output 'contact.time' is the first-contact time of automatic contact (MODEL.md section 4); "
                        "this case gives contact.point and contact.normal, so its exchange is at the case state "
                        "(leave contact.time out)")
    if not 0.0 <= float(smoothing) < 1.0:
        raise CaseError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")
    sizes = tuple(len(a) for a in axes.values())
    shape = _shape(dict(zip(paths, sizes)), mode)
    total = math.prod(shape)
    if total > np.iinfo(np.int64).max:
        raise CaseError(f"the sweep has {total:.3g} points, more than a 64-bit index counts ({np.iinfo(np.int64).max:.3g}): "
                        "sweep fewer values")
    if index_range is None:
        lo, hi = 0, total
    else:
        if isinstance(index_range, (str, bytes)) or not hasattr(index_range, "__len__") or len(index_range) != 2:
            raise CaseError(f"index_range = {index_range!r}: give two whole numbers (lo, hi)")
        try:
            lo, hi = (operator.index(v) for v in index_range)
        except TypeError:
            raise CaseError(f"index_range = {tuple(index_range)}: lo and hi must be whole numbers") from None
    if not 0 <= lo <= hi <= total:
        raise CaseError(f"index_range = {index_range}: must satisfy 0 <= lo <= hi <= {total}")
    n_points = hi - lo

    devices = tuple(jax.devices() if devices is None else devices)
    per_device = DEFAULT_CHUNK if chunk_size is None else _whole_number(chunk_size, "chunk_size")
    if per_device <= 0:
        raise CaseError(f"chunk_size = {chunk_size}: must be positive")
    n_rows = per_device * len(devices)
    # small sweeps: one short chunk, of a length rounded up (``_bucket``) so that other sizes reuse its programs
    n_rows = min(n_rows, _bucket(-(-max(n_points, 1) // len(devices))) * len(devices))

    # float32 far from the origin: the scene, swept positions included, is solved about the CGs' midpoint
    # (case.scene_origin), and contact.point outputs are moved back, in float64
    origin = scene_origin(case.inputs, [v for p, v in axes.items() if xy_index(p) is not None])
    moved = {} if origin is None else {p: origin_offset(p, origin) for p in (*paths, *outputs)}
    moved = {p: float(off) for p, off in moved.items() if off is not None}
    inputs = case.inputs if origin is None else move_scene(case.inputs, origin, case.auto_point)
    swept = {p: a - moved.get(p, 0.0) for p, a in axes.items()}
    warn_far_from_origin(inputs, [v for p, v in swept.items() if p in moved], what="the swept scene",
                         about="the origin" if origin is None else "its CGs' midpoint", auto_point=case.auto_point)
    base = as_arrays(inputs)
    dtype = jnp.result_type(float)
    out_dtype = np.dtype(output_dtype or dtype)
    quick = n_points <= QUICK_POINTS and all(d.platform == "cpu" for d in devices)
    # a whole sweep in one chunk: its axes padded and its sizes an argument, for any size in the same buckets;
    # a larger one (or a range of one) keeps its exact axes (a zip of 10^8 samples is not padded) and sizes
    one_chunk = total <= n_rows
    static_sizes = None if one_chunk else sizes
    status_jit, impulse_jit, solve_jit = _compiled(paths, input_ties(case, paths), outputs, mode, n_rows, static_sizes,
                                                   case.auto_point, case.auto_normal, float(smoothing), out_dtype,
                                                   devices, quick)
    index_dtype = jnp.int64 if jax.config.jax_enable_x64 else jnp.int32
    if total > np.iinfo(np.int32).max and index_dtype == jnp.int32:
        raise CaseError(f"{total} points need 64-bit indices: enable jax_enable_x64")
    dev_axes = tuple(_padded(a, dtype) if one_chunk else jnp.asarray(a, dtype=dtype) for a in swept.values())
    dev_sizes = jnp.asarray(sizes, dtype=index_dtype)
    total_arr = jnp.asarray(total, dtype=index_dtype)

    store = {}
    if keep:
        itemsize = sum(1 if p.endswith(".sliding") else 8 if p in moved else out_dtype.itemsize for p in outputs)
        _check_memory(n_points * (itemsize + 1), f"keeping {n_points} points of {len(outputs)} outputs",
                      "pass keep=False and on_chunk (ks-jax sweep --out writes chunk by chunk), index_range, "
                      "output_dtype=np.float32 or fewer outputs")
        for p in outputs:
            store[p] = np.empty(n_points, dtype=bool if p.endswith(".sliding") else np.float64 if p in moved
                                else out_dtype)
        store["status"] = np.empty(n_points, dtype=np.int8)
    counts = np.zeros(256, dtype=np.int64)
    undefined = {p: 0 for p in outputs if undefined_kind(p)}

    show = n_points > n_rows if progress is None else bool(progress)  # one chunk: one step, nothing to show
    bar = _Progress(n_points, show, PROGRESS_DELAY if progress is None else 0.0)
    t0 = time.perf_counter()

    def launch(start):
        s = jnp.asarray(start, dtype=index_dtype)
        vals, prepared = status_jit(s, dev_axes, dev_sizes, total_arr, base)
        stage = impulse_jit(base, vals, prepared)
        return start, solve_jit(base, vals, prepared, stage)

    def collect(item):
        start, out = item
        n = min(n_rows, hi - start)
        chunk = {k: np.asarray(out[k])[:n] for k in (*outputs, "status")}  # in the order asked (jit sorts keys)
        for p in outputs:
            if p in moved:
                chunk[p] = chunk[p].astype(np.float64) + moved[p]
        counts[:] += np.bincount(chunk["status"].astype(np.int64) & 0xFF, minlength=256)
        if undefined:
            solved = ~_invalid_rows(chunk["status"])
            for p in undefined:
                undefined[p] += int(np.count_nonzero(np.isnan(chunk[p]) & solved))
        a, b = start - lo, start - lo + n
        if keep:
            for k, v in chunk.items():
                store[k][a:b] = v
        if on_chunk is not None:
            on_chunk(start, start + n, chunk)
        bar.update(n)

    try:
        pending = None
        for start in range(lo, hi, n_rows):
            item = launch(start)  # dispatched asynchronously: overlaps the previous transfer
            if pending is not None:
                collect(pending)
            pending = item
        if pending is not None:
            collect(pending)
    finally:
        bar.close()
    seconds = time.perf_counter() - t0

    result_shape = shape if (index_range is None) else (n_points,)
    if keep:
        store = {k: v.reshape(result_shape) for k, v in store.items()}
    status_counts = {STATUS_TEXT.get(c, status_text(c)): int(counts[c]) for c in np.flatnonzero(counts)}
    return SweepResult(store, axes, result_shape, mode, n_points, status_counts, seconds, (lo, hi), outputs,
                       undefined=undefined)


# ---------------------------------------------------------------------------------------
# command line: ks-jax sweep FILE --over PATH=START:STOP:N ... --out results.csv|.npz|.parquet


def add_arguments(parser):
    parser.add_argument("file", help="a case file (JSON or TOML): one case, or several with --case K")
    parser.add_argument("--over", action="append", required=True, metavar="PATH=START:STOP:N",
                        help="an input path and its values: START:STOP:N (N evenly spaced values), "
                             "V1,V2,..., or random values uniform:LO:HI or normal:MEAN:SD (with --samples); "
                             "bare numbers are SI except angles (deg) and rates (deg/s); "
                             "unit strings allowed, e.g. vehicles[1].speed=10mph:60mph:51")
    parser.add_argument("--output", action="append", metavar="PATH",
                        help="an output path of MODEL.md section 4 (repeat; default: the main results)")
    parser.add_argument("--mode", choices=("grid", "zip"), default=None,
                        help="grid: cartesian product (default); zip: the k-th values of every path together "
                             "(the default with random values)")
    parser.add_argument("--samples", type=int, default=None, metavar="N",
                        help="number of random values of each PATH=uniform:LO:HI or PATH=normal:MEAN:SD (Monte Carlo)")
    from .cli import seed_option, smoothing_option

    parser.add_argument("--seed", type=seed_option, default=0, help="seed of the random values (default 0)")
    parser.add_argument("--out", required=True, metavar="FILE", help="results file: .csv, .npz or .parquet")
    parser.add_argument("--case", type=int, default=None, metavar="K", help="the K-th case (0-based) of a multi-case file")
    parser.add_argument("--chunk-size", type=int, default=None, help="rows per device and chunk (default 16384)")
    parser.add_argument("--smoothing", type=smoothing_option, default=0.0, help="smooth friction cone, tau in [0, 1)")
    parser.add_argument("--float32", action="store_true", help="store the results as float32")
    parser.add_argument("--units", choices=("si", "us"), default="si",
                        help="units of the file: si (default) or us (mph, ft, lbf s, ft lbf, deg, deg/s, lb; "
                             "each column's unit in its name, e.g. 'vehicles[1].speed [mph]')")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--plot", metavar="PNG", help="also draw the outputs over the swept inputs (US units): a map "
                        "for two inputs, a line for one, histograms for --mode zip (matplotlib)")


class Draws(NamedTuple):
    """Random values of one input (``--over PATH=uniform:LO:HI`` or ``normal:MEAN:SD``), SI."""

    path: str
    law: str
    a: float
    b: float

    def draw(self, n, rng):
        """n values from ``rng`` (a ``numpy.random.Generator``)."""
        if self.law == "uniform":
            return rng.uniform(self.a, self.b, n)
        return rng.normal(self.a, self.b, n)


def parse_over(text):
    """'PATH=START:STOP:N' or 'PATH=V1,V2,...' -> (path, SI values); 'PATH=uniform:LO:HI' or
    'PATH=normal:MEAN:SD' -> (path, ``Draws``), drawn by ``draw_over``. A grid typed in plain SI numbers
    has its values within 2 ulp of a 15-digit decimal made that decimal (linspace's rounding undone: 0.05,
    not 0.049999999999999996)."""
    from .units import UnitError, parse_quantity

    if "=" not in text:
        raise CaseError(f"--over {text!r}: expected PATH=START:STOP:N, PATH=V1,V2,..., PATH=uniform:LO:HI "
                        "or PATH=normal:MEAN:SD")
    path, spec = (s.strip() for s in text.split("=", 1))
    _input_leaf(path)
    kind = input_kind(path)

    def q(v):
        try:
            return parse_quantity(v.strip(), kind)
        except UnitError as err:
            raise CaseError(f"--over {path}: {v.strip()!r}: {err}") from None

    parts = spec.split(":")
    law = parts[0].strip().lower()
    if law in ("uniform", "normal"):
        names = ("LO", "HI") if law == "uniform" else ("MEAN", "SD")
        if len(parts) != 3:
            raise CaseError(f"--over {path}={spec}: expected {law}:{':'.join(names)}")
        a, b = q(parts[1]), q(parts[2])
        for name, part, value in zip(names, parts[1:], (a, b)):
            if not math.isfinite(value):
                raise CaseError(f"--over {path}: {name} = {part.strip()!r} must be a finite number")
        if law == "uniform" and a > b:
            raise CaseError(f"--over {path}={spec}: LO must not exceed HI")
        if law == "normal" and b < 0:
            raise CaseError(f"--over {path}={spec}: SD must be >= 0")
        return path, Draws(path, law, a, b)
    if len(parts) == 3:
        try:
            n = int(parts[2])
        except ValueError:
            raise CaseError(f"--over {path}: N = {parts[2]!r} must be a whole number") from None
        if n < 1:
            raise CaseError(f"--over {path}: N = {n} must be at least 1")
        _check_memory(8 * n, f"--over {path}: a grid of N = {n} values", "give fewer values")
        ends = q(parts[0]), q(parts[1])
        for name, part, value in zip(("START", "STOP"), parts, ends):
            if not math.isfinite(value):
                raise CaseError(f"--over {path}: {name} = {part.strip()!r} must be a finite number")
        if n == 1 and ends[0] != ends[1]:
            raise CaseError(f"--over {path}={spec}: N = 1 would solve START alone and leave STOP out: give N >= 2, "
                            "or one value (PATH=V)")
        grid = np.linspace(*ends, n)
        return path, _typed_back(grid) if all(_plain(t) == v for t, v in zip(parts, ends)) else grid
    if len(parts) == 1:
        if any(not v.strip() for v in spec.split(",")):
            raise CaseError(f"--over {path}={spec}: a value is missing between commas (V1,V2,...)")
        values = [(v.strip(), q(v)) for v in spec.split(",")]
        for text, value in values:
            if not math.isfinite(value):
                raise CaseError(f"--over {path}: {text!r} must be a finite number")
        return path, np.array([value for _, value in values])
    raise CaseError(f"--over {path}={spec}: expected START:STOP:N, V1,V2,..., uniform:LO:HI or normal:MEAN:SD")


def _plain(text):
    """The number a bare numeral means (None for anything with a unit): a grid typed in SI numbers is
    snapped to its decimals (0:0.3:7 gives 0.05, not 0.049999999999999996); one converted from mph or
    deg is left as converted (the file in US units types it back)."""
    try:
        return float(text)
    except ValueError:
        return None


def draw_over(specs, mode, samples, seed):
    """({path: SI values}, mode) from ``parse_over``'s (path, values or Draws): the draws made with
    ``numpy.random.default_rng(seed)``, ``samples`` each, in the order given (zip mode). Values given as
    numbers stay as they are."""
    _check_distinct([p for p, _ in specs], "--over")
    draws = [p for p, v in specs if isinstance(v, Draws)]
    if not draws:
        if samples is not None:
            raise CaseError("--samples N is for random values: give --over PATH=uniform:LO:HI or PATH=normal:MEAN:SD")
        return dict(specs), mode or "grid"
    if samples is None or samples < 1:
        raise CaseError(f"--over {draws[0]}=...: random values need --samples N (N >= 1), got {samples}")
    if mode == "grid":
        raise CaseError(f"--over {draws[0]}=...: random values are samples, swept together (--mode zip), not a grid")
    rng = np.random.default_rng(seed)
    return {p: v.draw(samples, rng) if isinstance(v, Draws) else v for p, v in specs}, "zip"


def _check_distinct(paths, what):
    """Refuse two paths that name one input ("vehicles[0].yaw_rate" is "vehicles[0].angular_velocity[2]";
    spaces do not count): the later would override the earlier, under the earlier's name."""
    seen = {}
    for p in paths:
        group, vi, name, idx = _input_leaf(p)
        key = (group, vi, name, tuple(sorted(idx)) if name == "inertia" else idx)  # [0][1] is [1][0]
        if key in seen:
            same = "twice" if seen[key] == p else f"and '{seen[key]}'"
            raise CaseError(f"{what} '{p}' {same}: both name the same input, so one would override the other; "
                            "give it once")
        seen[key] = p


def _shape(sizes, mode):
    """A sweep's result shape from {path: number of values}: one axis per path ("grid") or one axis
    ("zip", which needs the same number for every path)."""
    counts = tuple(sizes.values())
    if mode != "zip":
        return counts
    if len(set(counts)) != 1:
        raise CaseError("sweep mode 'zip' needs the same number of values for every path, got "
                        + ", ".join(f"{p}: {n}" for p, n in sizes.items()))
    return counts[:1]


def _grid_inputs(axes, mode, lo, hi):
    """path -> the swept input value (SI) at flat indices lo .. hi - 1 (``SweepResult.inputs``)."""
    idx = np.arange(lo, hi)
    if mode == "zip":
        return {p: np.asarray(v)[idx] for p, v in axes.items()}
    pos = np.unravel_index(idx, tuple(len(v) for v in axes.values()))
    return {p: np.asarray(v)[k] for (p, v), k in zip(axes.items(), pos)}


def _columns(axes, mode, lo, hi, outputs):
    """Flat columns of points lo .. hi - 1: the swept inputs, then ``outputs`` (path -> values, with
    "status" among them) in their order, the status code (int32) last."""
    cols = _grid_inputs(axes, mode, lo, hi)
    cols.update((p, np.ravel(v)) for p, v in outputs.items() if p != "status")
    cols["status"] = np.ravel(outputs["status"]).astype(np.int32)
    return cols


def _check_units(units, what):
    if units not in ("si", "us"):
        raise CaseError(f"units = {units!r}: {what} must be 'si' or 'us'")


def _in_units(path, values, kind, units):
    """(name, values) of a column: as given in "si"; in "us", the values in the unit of
    ``units.US_DISPLAY[kind]`` (floats only, their dtype kept) and the unit in the name."""
    values = np.asarray(values)
    if units == "si":
        return path, values
    scale, unit = U.US_DISPLAY[kind]
    if scale != 1.0 and np.issubdtype(values.dtype, np.floating):
        values = (values / scale).astype(values.dtype)
    return (f"{path} [{unit}]" if unit else path), values


def _axes_in_units(axes, units):
    """{name: values} of the swept inputs ``axes`` (path -> values) by ``_in_units``; a converted
    value is given as its 15-significant-digit form where that lies within two units in the last
    place (the conversion's own rounding): 30 mph, not 29.999999999999996."""
    named = dict(_in_units(p, v, input_kind(p), units) for p, v in axes.items())
    if units == "si":
        return named
    return {name: _typed_back(v) if name.endswith("]") else v for name, v in named.items()}


def _typed_back(values):
    """``values`` (floats) with each one that is within 2 ulp of a 15-significant-digit number replaced
    by that number (undoing the rounding of a unit conversion of a value typed in short decimals)."""
    if not np.issubdtype(values.dtype, np.floating) or values.dtype.itemsize < 8:
        return values
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        digits = np.where(values == 0, 0, np.floor(np.log10(np.abs(values))))
        scale = 10.0 ** (14 - digits)
        short = np.round(values * scale) / scale
    near = np.isfinite(short) & (np.abs(short - values) <= 2 * np.spacing(np.abs(values)))
    return np.where(near, short, values)


def _outputs_in_units(outputs, units):
    """{name: values} of ``outputs`` (path -> values, "status" among them) by ``_in_units``."""
    return dict((p, v) if p == "status" else _in_units(p, v, output_kind(p), units) for p, v in outputs.items())


CSV_HINT_POINTS = 100_000  # from this many points, ``ks-jax sweep`` without pyarrow suggests it for a .csv


def _arrow_csv():
    """pyarrow's csv module, or None without pyarrow (``ResultWriter`` then writes with ``csv``)."""
    try:
        import pyarrow.csv
    except ImportError:
        return None
    return pyarrow.csv


def _invalid_rows(codes):
    """Which status codes are "invalid: ..." (every code from ``INVALID_NONFINITE`` on)."""
    return np.asarray(codes) >= INVALID_NONFINITE


def _missing_flags(cols):
    """``cols`` with each flag (bool) column an object array holding None on the invalid rows, where
    there are any (their numbers are NaN; a False would read as a result)."""
    invalid = _invalid_rows(cols["status"])
    if not invalid.any():
        return cols
    return {k: np.where(invalid, None, v) if v.dtype == bool else v for k, v in cols.items()}


def _arrow_table(cols):
    """A pyarrow table of ``cols`` (name -> flat array, "status" among them); a flag (bool) of an
    invalid row is null (its numbers are NaN), not a false that would read as a result."""
    import pyarrow as pa

    invalid = _invalid_rows(cols["status"])
    return pa.table({k: pa.array(v, mask=invalid) if v.dtype == bool and invalid.any() else v
                     for k, v in cols.items()})


def _status_texts(codes):
    """The status text of each code (an object array sharing one string per distinct code)."""
    distinct, which = np.unique(codes, return_inverse=True)
    return np.array([STATUS_TEXT.get(c, status_text(c)) for c in distinct.tolist()], dtype=object)[which]


class ResultWriter:
    """Writes a sweep to ``out`` (.csv, .npz or .parquet) chunk by chunk, as ``sweep`` computes it:
    pass ``writer.chunk`` as ``on_chunk`` (with ``keep=False``), then call ``close()`` (or ``abort()``
    on an error). Memory stays at a few chunks whatever the number of points (``ks-jax sweep``).

    .csv: one row per point: the swept inputs, the outputs, ``status``, ``status_text``; an invalid
    row's numbers are NaN and its flags (``contact.sliding``) empty (null in .parquet). Where
    pyarrow is installed its CSV writer formats the numbers (shortest text that reads back as the same
    float, as Python's, but 1.0 is written "1" and 1e-05 "0.00001"; float32 results as float32, so
    "0.1" where the csv module writes 0.10000000149011612), writes booleans true / false and
    quotes every text; without pyarrow the ``csv`` module writes it (1.0, 1e-05, True / False, texts
    quoted only where they must be), several times slower: Python's float formatting is the cost.
    .parquet: the same columns (pyarrow), in row groups of about 2^18 points.
    .npz: one array per output in the result's shape, ``axis:<path>`` for the axes, the status codes
    and texts (a bool array has no empty value: an invalid row's flag is False there, read its
    status). Each array is appended to a temporary .npy file beside ``out``, chunk by chunk; ``close``
    stores them in ``out`` (uncompressed, as ``np.savez``), so the disk briefly holds them twice.
    The file is written as ``.<name>.partial`` beside ``out`` and renamed to ``out`` by ``close``: a
    sweep that fails leaves an earlier ``out`` as it was.
    ``units="us"``: every swept input and output in the units of ``units.US_DISPLAY`` (mph, ft, lbf s,
    ft lbf, deg, deg/s, lb), its unit in its name ("vehicles[1].speed [mph]", in every format);
    dimensionless ones, booleans and the status as they are; a swept value typed as 25 mph is 25, not
    the 24.999999999999996 that comes back from m/s. Default "si": SI, names as paths.
    """

    ROW_GROUP = 1 << 18

    def __init__(self, out, axes, mode, shape, first=0, units="si"):
        """axes: path -> the swept values (SI); shape: the result's shape; first: the flat index of
        its first point (a sweep's ``index_range[0]``); units: "si" or "us" (the file's units)."""
        _check_units(units, "the units of a results file")
        self.out = Path(out)
        self.kind = self.out.suffix.lower()
        if self.kind not in (".csv", ".npz", ".parquet"):
            raise CaseError(f"--out {out}: unknown file type '{self.out.suffix}' (use .csv, .npz or .parquet)")
        from .cli import check_output_file

        check_output_file(out, "--out")
        if self.kind == ".parquet":
            try:
                import pyarrow  # noqa: F401
            except ImportError:
                raise CaseError("parquet output needs pyarrow: pip install 'ks-jax[parquet]' "
                                "(or write .csv / .npz)") from None
        self.units, self.mode, self.shape, self.first = units, mode, tuple(shape), int(first)
        # the swept values (and below, the outputs) as the file holds them, by the names it gives them
        self.axes = _axes_in_units(axes, units)
        self.points = math.prod(self.shape)
        self._partial = self.out.with_name(f".{self.out.name}.partial")
        self._file = self._parquet = self._tmpdir = None
        self._arrays, self._pending, self._written = {}, [], 0
        self._arrow_csv = _arrow_csv() if self.kind == ".csv" else None
        # the swept values as the columns show them: in a .csv of a grid written by the csv module,
        # each value's text (what it writes for the Python float), formatted once instead of once per row
        self._column_axes = self.axes
        if self.kind == ".csv" and self._arrow_csv is None and mode != "zip":
            self._column_axes = {p: np.array([str(x) for x in np.asarray(v).tolist()], dtype=object)
                                 for p, v in self.axes.items()}
        self.seconds = self.chunk_seconds = 0.0  # spent writing: in all, and inside ``chunk``

    def chunk(self, lo, hi, chunk):
        """Points lo .. hi - 1 (flat indices, in order): ``chunk`` maps each output path and "status"
        to an array of hi - lo values."""
        t = time.perf_counter()
        try:
            self._chunk(lo, hi, chunk)
        finally:
            self.chunk_seconds += time.perf_counter() - t
            self.seconds += time.perf_counter() - t

    def _chunk(self, lo, hi, chunk):
        if lo - self.first != self._written:
            raise CaseError(f"{self.out}: points {lo}..{hi - 1} arrived after {self._written} of {self.points}")
        if self.units != "si":
            chunk = _outputs_in_units(chunk, self.units)
        if self.kind == ".npz":
            self._npz_chunk(chunk)
        else:
            cols = _columns(self._column_axes, self.mode, lo, hi, chunk)
            cols["status_text"] = _status_texts(cols["status"])
            if self.kind == ".csv" and self._arrow_csv is None:
                self._csv_chunk(cols)
            else:
                table = _arrow_table(cols)
                if self.kind == ".csv":
                    self._arrow_csv_chunk(table)
                else:
                    self._pending.append(table)
                    if sum(t.num_rows for t in self._pending) >= self.ROW_GROUP:
                        self._flush_parquet()
        self._written += hi - lo

    def _csv_chunk(self, cols):
        import csv

        if self._file is None:
            self._file = self._partial.open("w", newline="")
            self._csv = csv.writer(self._file)
            self._csv.writerow(list(cols))
        texts = (c.tolist() for c in _missing_flags(cols).values())  # a flag of an invalid row: ""
        self._csv.writerows(zip(*texts))

    def _arrow_csv_chunk(self, table):
        if self._file is None:
            options = self._arrow_csv.WriteOptions(quoting_style="needed")
            self._file = self._arrow_csv.CSVWriter(str(self._partial), table.schema, write_options=options)
        self._file.write_table(table)

    def _flush_parquet(self):
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self._pending:
            return
        table = pa.concat_tables(self._pending)
        if self._parquet is None:
            self._parquet = pq.ParquetWriter(self._partial, table.schema)
        self._parquet.write_table(table)
        self._pending = []

    def _npz_chunk(self, chunk):
        import tempfile

        if self._tmpdir is None:
            self._tmpdir = tempfile.TemporaryDirectory(prefix=self.out.name + ".", dir=self.out.parent)
        for k, (p, v) in enumerate(chunk.items()):
            if p not in self._arrays:
                path = Path(self._tmpdir.name) / f"{k}.npy"
                f = path.open("wb")
                header = {"descr": np.lib.format.dtype_to_descr(v.dtype), "fortran_order": False, "shape": self.shape}
                np.lib.format.write_array_header_2_0(f, header)
                self._arrays[p] = (path, f)
            self._arrays[p][1].write(np.ascontiguousarray(v).tobytes())

    def close(self):
        """Finish the file (.npz: store the arrays). Raises if not every point was written."""
        t = time.perf_counter()
        try:
            if self._written != self.points:
                raise CaseError(f"{self.out}: {self._written} of {self.points} points written")
            if self.points == 0:
                raise CaseError(f"{self.out}: the sweep has no points to write")
            if self.kind == ".csv":
                self._file.close()
            elif self.kind == ".parquet":
                self._flush_parquet()
                self._parquet.close()
            else:
                self._write_npz()
            self._file = self._parquet = None
            self._partial.replace(self.out)
        finally:
            self.abort()
            self.seconds += time.perf_counter() - t

    def _write_npz(self):
        import io
        import zipfile

        for _, f in self._arrays.values():
            f.close()
        codes = np.array(sorted(STATUS_TEXT))
        small = {f"axis:{p}": np.asarray(v) for p, v in self.axes.items()}
        small.update(status_codes=codes, status_texts=np.array([STATUS_TEXT[c] for c in codes]))
        with zipfile.ZipFile(self._partial, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            for p, (path, _) in self._arrays.items():
                zf.write(path, f"{p}.npy")
            for name, v in small.items():
                buf = io.BytesIO()
                np.save(buf, v)
                zf.writestr(f"{name}.npy", buf.getvalue())

    def abort(self):
        """Close what is open and delete the unfinished file (``out`` itself is left as it was)."""
        if self._file is not None:
            self._file.close()
            self._file = None
        if self._parquet is not None:
            self._parquet.close()
            self._parquet = None
        for _, f in self._arrays.values():
            f.close()
        self._arrays = {}
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None
        self._partial.unlink(missing_ok=True)


def write_results(result: SweepResult, out, units="si"):
    """Write a kept sweep (``SweepResult``) to .csv (one row per point), .npz (arrays) or .parquet
    (pyarrow), in the format of ``ks-jax sweep`` (``ResultWriter``); units: "si" or "us"."""
    lo, hi = result.index_range
    writer = ResultWriter(out, result.axes, result.mode, result.shape, first=lo, units=units)
    flat = {p: np.ravel(v) for p, v in result.outputs.items()}
    try:
        for a in range(0, hi - lo, DEFAULT_CHUNK):
            b = min(hi - lo, a + DEFAULT_CHUNK)
            writer.chunk(lo + a, lo + b, {p: v[a:b] for p, v in flat.items()})
        writer.close()
    except BaseException:
        writer.abort()
        raise


def run(args) -> int:
    from .case import load_cases
    from .cli import raise_if_stopped

    cases = load_cases(args.file)
    if args.case is None:
        if len(cases) != 1:
            raise CaseError(f"{args.file} holds {len(cases)} cases: choose one with --case K (0-based)")
        case = cases[0]
    else:
        if not 0 <= args.case < len(cases):
            raise CaseError(f"--case {args.case}: {args.file} holds {len(cases)} cases (0..{len(cases) - 1})")
        case = cases[args.case]
    if not case.valid:
        raise CaseError(case.error)
    over, mode = draw_over([parse_over(t) for t in args.over], args.mode, args.samples, args.seed)
    shape = _shape({p: len(v) for p, v in over.items()}, mode)  # sweep's rule, checked before a file exists
    sample = _plot_sample(args.plot, over, mode, shape)  # checked before anything is solved
    writer = ResultWriter(args.out, over, mode, shape, units=args.units)  # chunk by chunk: memory stays bounded

    def on_chunk(lo, hi, chunk):
        raise_if_stopped()  # a Ctrl-C or kill that a library caught while the chunk was solved
        writer.chunk(lo, hi, chunk)
        if sample is not None:
            sample.chunk(lo, hi, chunk)

    t = time.perf_counter()
    try:
        result = sweep(case, over, outputs=args.output, mode=mode, chunk_size=args.chunk_size,
                       smoothing=args.smoothing, progress=False if args.no_progress else None,
                       output_dtype=np.float32 if args.float32 else None, on_chunk=on_chunk, keep=False)
        raise_if_stopped()
        writer.close()
    except BaseException:
        writer.abort()
        raise
    result = replace(result, seconds=max(result.seconds - writer.chunk_seconds, 0.0))  # solving alone
    print(f"ks-jax sweep: {case.name}")
    print(f"  {result.summary()}")
    if args.samples is not None:
        print(f"  random values: {args.samples} per path, seed {args.seed}")
    print(f"  written to {args.out} in {writer.seconds:.3g} s ({time.perf_counter() - t:.3g} s in all)")
    if writer.kind == ".csv" and writer._arrow_csv is None and writer.points >= CSV_HINT_POINTS:
        print("  (a large .csv is written several times faster with pyarrow installed: "
              "pip install 'ks-jax[parquet]'; or write .npz / .parquet)")
    if sample is not None:
        from .plot import save_sweep_view

        save_sweep_view(sample.result(result), args.plot)
        print(f"  drawn to {args.plot}")
    return 0


def _plot_sample(path, over, mode, shape):
    """A ``SweepSample`` for ``--plot PATH`` (None without it), after the checks a picture needs."""
    if path is None:
        return None
    from .plot import check_picture_path

    check_picture_path(path)
    if mode != "zip" and len(over) > 2:
        raise CaseError(f"--plot draws a sweep over one or two inputs; this one has {len(over)} "
                        f"({', '.join(over)}): leave --plot out, or sweep fewer inputs")
    return SweepSample(over, mode, shape)
