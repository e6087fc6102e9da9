"""A sweep's points as flat columns (one row per point), in SI or US units: what ``SweepResult.table``
returns and what results files hold."""

from __future__ import annotations

import numpy as np

from .. import units as U
from ..case import input_kind, output_kind
from ..case.errors import CaseError
from ..model.types import INVALID_NONFINITE, STATUS_TEXT, status_text


def grid_inputs(axes, mode, lo, hi):
    """path -> the swept input value (SI) at flat indices lo .. hi - 1 (``SweepResult.inputs``)."""
    idx = np.arange(lo, hi)
    if mode == "zip":
        return {p: np.asarray(v)[idx] for p, v in axes.items()}
    pos = np.unravel_index(idx, tuple(len(v) for v in axes.values()))
    return {p: np.asarray(v)[k] for (p, v), k in zip(axes.items(), pos)}


def columns(axes, mode, lo, hi, outputs):
    """Flat columns of points lo .. hi - 1: the swept inputs, then ``outputs`` (path -> values, with
    "status" among them) in their order, the status code (int32) last."""
    cols = grid_inputs(axes, mode, lo, hi)
    cols.update((p, np.ravel(v)) for p, v in outputs.items() if p != "status")
    cols["status"] = np.ravel(outputs["status"]).astype(np.int32)
    return cols


def check_units(units, what):
    if units not in ("si", "us"):
        raise CaseError(f"units = {units!r}: {what} must be 'si' or 'us'")


def in_units(path, values, kind, units):
    """(name, values) of a column: as given in "si"; in "us", the values in the unit of
    ``units.US_DISPLAY[kind]`` (floats only, their dtype kept) and the unit in the name."""
    values = np.asarray(values)
    if units == "si":
        return path, values
    scale, unit = U.US_DISPLAY[kind]
    if scale != 1.0 and np.issubdtype(values.dtype, np.floating):
        values = (values / scale).astype(values.dtype)
    return (f"{path} [{unit}]" if unit else path), values


def axes_in_units(axes, units):
    """{name: values} of the swept inputs ``axes`` (path -> values) by ``in_units``; a converted
    value is given as its 15-significant-digit form where that lies within two units in the last
    place (the conversion's own rounding): 30 mph, not 29.999999999999996."""
    named = dict(in_units(p, v, input_kind(p), units) for p, v in axes.items())
    if units == "si":
        return named
    return {name: typed_back(v) if name.endswith("]") else v for name, v in named.items()}


def typed_back(values):
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


def outputs_in_units(outputs, units):
    """{name: values} of ``outputs`` (path -> values, "status" among them) by ``in_units``."""
    return dict((p, v) if p == "status" else in_units(p, v, output_kind(p), units) for p, v in outputs.items())


def invalid_rows(codes):
    """Which status codes are "invalid: ..." (every code from ``INVALID_NONFINITE`` on); NumPy or JAX arrays
    (inside a program too)."""
    return (codes if hasattr(codes, "dtype") else np.asarray(codes)) >= INVALID_NONFINITE


def missing_flags(cols):
    """``cols`` with each flag (bool) column an object array holding None on the invalid rows, where
    there are any (their numbers are NaN; a False would read as a result)."""
    invalid = invalid_rows(cols["status"])
    if not invalid.any():
        return cols
    return {k: np.where(invalid, None, v) if v.dtype == bool else v for k, v in cols.items()}


def status_texts(codes):
    """The status text of each code (an object array sharing one string per distinct code)."""
    distinct, which = np.unique(codes, return_inverse=True)
    return np.array([STATUS_TEXT.get(c, status_text(c)) for c in distinct.tolist()], dtype=object)[which]
