"""What a sweep returns (``SweepResult``), and thinned views of it for pictures."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from ..case import UNDEFINED_REASONS, undefined_kind
from ..case.errors import CaseError
from .columns import axes_in_units, check_units, columns, grid_inputs, missing_flags, outputs_in_units, status_texts


@dataclass
class SweepResult(Mapping):
    """Results of a sweep: a mapping output path -> array (grid shape, or (n,) for zip and
    index ranges), ``"status"`` (int8 codes, ``ks_jax.status_text``) always among them.

    axes: path -> the values (SI) swept along each grid axis (zip: the samples).
    shape: the result shape. mode: "grid" or "zip". points: number of points solved.
    status_counts: status text -> number of points. seconds: wall time of solving the points;
    compile_seconds: of compiling (or finding compiled) its program before, apart, so that the rate
    (points / seconds) is the solving rate of a first sweep too.
    names: the case's vehicle names, by index (for labels: ``vehicles[1].speed (Kia K5)``).
    undefined: output path -> the number of solved points (status not "invalid") where it is NaN
    because the model leaves it undefined there (``case.defined_output``: a PDOF or impulse direction
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
    compile_seconds: float = 0.0
    names: tuple = ()

    def __getitem__(self, key):
        return self.outputs[key]

    def __iter__(self):
        return iter(self.outputs)

    def __len__(self):
        return len(self.outputs)

    def inputs(self):
        """path -> the input value (SI) at every point, flat (in the order of the outputs)."""
        return grid_inputs(self.axes, self.mode, *self.index_range)

    def table(self, units="si"):
        """Flat columns (one row per point): the inputs, the outputs, the status code and its text, as a
        .csv of ``write_results`` holds them (``pandas.DataFrame(result.table())`` makes a data frame): a
        flag (``contact.sliding``) of an invalid row is None (an object column where there is one).
        units: "si", or "us" (mph, ft, lbf s, ft lbf, deg, deg/s, lb; the unit in each name)."""
        check_units(units, "units")
        check_kept(self)
        cols = columns(axes_in_units(self.axes, units), self.mode, *self.index_range,
                        outputs_in_units(self.outputs, units))
        cols["status_text"] = status_texts(cols["status"])
        return missing_flags(cols)

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
                f"({rate:.3g} points/s), compiled first in {self.compile_seconds:.3g} s; status: {counts}")
        return text + "".join(f"\n  undefined (NaN) at {n} solved point{'s' * (n != 1)}: {p}, where "
                              f"{UNDEFINED_REASONS[undefined_kind(p)]}" for p, n in self.undefined.items() if n)


# what a picture draws of a large sweep: more than this is finer than a figure's pixels (a line of 4000
# points, a map of 250 x 250 cells) or a histogram's bins, and costs seconds and memory to draw
PLOT_LIMITS = {1: 4000, 2: 250}
PLOT_SAMPLES = 200_000


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
