"""How rows are computed on the devices at hand: the plan (docs/devices.md).

A CPU and an accelerator (a GPU) want the same rows computed differently. A CPU runs a program's loops one
after another over memory that is also the host's: it is fastest over chunks of rows that fit its cache,
each stage of the exchange stored before the next reads it. An accelerator runs many rows at once from
memory of its own: it is fastest over chunks as large as its free memory allows, with XLA free to fuse the
stages, its results copied to the host while it computes the next chunk.

That choice is data: a ``Plan`` (frozen, hashable), made once at an entry point (``exchange_batch``, ``sweep``,
``solve``, ``fit.reconstruct*``, the command line) from the devices the rows go to, or given there, and passed
down as a static argument, so that it is part of the key of every compiled and kept program: a program traced
for one path is never run on the other. ``Plan("accelerator")`` on a CPU takes the accelerator's path there, so
that its logic is exercised and tested where no accelerator is: both paths compute the same values. The
physics (``ks_jax.model``) knows nothing of devices; its one CPU-only form, the stored sines and cosines of
``model.linalg.materialize``, is chosen by the platform a program is compiled for (``jax.lax.platform_dependent``).
The environment variable ``KS_JAX_PATH`` ("cpu" or "accelerator") is read by the command line alone
(``path_from_environment``).
"""

from __future__ import annotations

import dataclasses
import os
from typing import NamedTuple

import jax
import numpy as np

CPU_CHUNK_ROWS = 1 << 14  # rows per chunk on a CPU: a stage's inputs and outputs within its last-level cache
# On an accelerator: the share of the device's free memory that one chunk's working set may take, the working
# set as a multiple of the rows' input and result bytes (XLA stores some intermediate values between its
# kernels), and the bounds of a chunk (a smaller one leaves the device idle between launches; a larger one
# gains nothing and delays the first results).
MEMORY_SHARE = 0.25
WORKING_SET = 4
MIN_ROWS, MAX_ROWS = 1 << 16, 1 << 23
FALLBACK_MEMORY = 8 << 30  # bytes assumed free on a device that reports no memory statistics

PATHS = ("cpu", "accelerator")


@dataclasses.dataclass(frozen=True)
class Plan:
    """How a batch's rows are computed. ``path``: "cpu" (the exchange's stages fenced apart, cache-sized
    chunks, a motion's rows in blocks, calls of a few hundred fits) or "accelerator" (one program XLA fuses
    freely, chunks from the device's free memory, results copied while the next chunk computes, calls of
    thousands of fits). ``chunk_rows``: rows per chunk of a batch or sweep; None, the path's own (``rows``).
    The dtype of the work is the inputs' (float64 where JAX's x64 is on): a plan does not change values.
    Hashable and compared by value, so that it can be a static argument of ``jax.jit``."""

    path: str = "cpu"
    chunk_rows: int | None = None

    def __post_init__(self):
        if self.path not in PATHS:
            raise ValueError(f"plan path = {self.path!r}: must be 'cpu' or 'accelerator'")
        if self.chunk_rows is not None and (isinstance(self.chunk_rows, bool) or int(self.chunk_rows) != self.chunk_rows
                                            or self.chunk_rows < 1):
            raise ValueError(f"plan chunk_rows = {self.chunk_rows!r}: must be a positive whole number of rows")

    @property
    def cpu(self) -> bool:
        """Whether this is the CPU's path."""
        return self.path == "cpu"

    @property
    def packed(self) -> bool:
        """Whether a watched motion carries its state packed (``model.interaction.interact(packed=...)``): on the
        accelerator's path, where a step's copies and kernels are its cost; not on the CPU's, where a copy costs
        what it copies and packing copies more."""
        return not self.cpu

    def rows(self, bytes_per_row: int, device=None) -> int:
        """Rows per chunk for rows of ``bytes_per_row`` input and result bytes: ``chunk_rows`` where given;
        else ``CPU_CHUNK_ROWS`` on the CPU's path, and on an accelerator's the largest power of two whose
        working set (``WORKING_SET`` times the rows' bytes) takes at most ``MEMORY_SHARE`` of ``device``'s free
        memory, within [``MIN_ROWS``, ``MAX_ROWS``]."""
        if self.chunk_rows is not None:
            return int(self.chunk_rows)
        if self.cpu:
            return CPU_CHUNK_ROWS
        fits = int(MEMORY_SHARE * free_bytes(device)) // max(int(bytes_per_row) * WORKING_SET, 1)
        rows = 1 << max(fits, 1).bit_length() - 1
        return min(max(rows, MIN_ROWS), MAX_ROWS)


def plan_for(plan=None, devices=None) -> Plan:
    """The plan of a call: ``plan`` as given (a ``Plan``, or "cpu" / "accelerator"), else the path of the
    devices the rows go to (``devices``, default JAX's default devices): the CPU's where they are all CPUs."""
    if isinstance(plan, Plan):
        return plan
    if plan is not None:
        return Plan(plan)
    devices = jax.devices() if devices is None else list(devices)
    return Plan("cpu" if all(d.platform == "cpu" for d in devices) else "accelerator")


def checked_devices(devices, where: str) -> tuple:
    """``devices`` as given to ``where`` (an entry point's name), as a tuple; default (None), this process's devices
    (``jax.local_devices()``). The rows are split over them along one axis, so they must be JAX devices, at least
    one, each once, all of one platform: a TypeError or ValueError naming ``where``, the value and the rule
    otherwise (a device's name, such as "cpu", is a plan's path: ``plan=``)."""
    if devices is None:
        return tuple(jax.local_devices())
    try:
        if isinstance(devices, (str, bytes)):
            raise TypeError
        devices = tuple(devices)
    except TypeError:
        raise TypeError(f"{where}: devices = {devices!r}: give a list of JAX devices (jax.devices() or part of it); "
                        "for the path the rows take, give plan='cpu' or plan='accelerator'") from None
    if not devices:
        raise ValueError(f"{where}: devices = []: give at least one JAX device (jax.devices())")
    for d in devices:
        if not isinstance(d, jax.Device):
            raise TypeError(f"{where}: devices holds {d!r}: each must be a JAX device (jax.devices())")
    if len(set(devices)) < len(devices):
        raise ValueError(f"{where}: devices = {list(devices)}: each device once (the rows are split among them)")
    platforms = sorted({d.platform for d in devices})
    if len(platforms) > 1:
        raise ValueError(f"{where}: devices of {' and '.join(platforms)}: give devices of one platform (the rows "
                         "are split among them in one program)")
    return devices


def path_from_environment() -> Plan | None:
    """The plan ``KS_JAX_PATH`` names (the command line's, read once there), None where it is unset or empty;
    ValueError for any other value."""
    kind = os.environ.get("KS_JAX_PATH", "")
    if kind and kind not in PATHS:
        raise ValueError(f"KS_JAX_PATH = {kind!r}: must be 'cpu' or 'accelerator' (or unset: the devices')")
    return Plan(kind) if kind else None


def free_bytes(device=None) -> int:
    """Bytes free on ``device`` (default: the first device) for XLA's buffers, from its memory statistics;
    ``FALLBACK_MEMORY`` where it gives none (a CPU, some backends)."""
    device = device or jax.devices()[0]
    try:
        stats = device.memory_stats() or {}
    except Exception:  # noqa: BLE001 (backends without statistics raise various errors)
        stats = {}
    limit = stats.get("bytes_limit") or stats.get("bytes_reservable_limit")
    if not limit:
        return FALLBACK_MEMORY
    return max(int(limit) - int(stats.get("bytes_in_use", 0)), 0)


class RowPlacement(NamedTuple):
    rows: jax.sharding.Sharding  # arrays with the rows first: split along them
    replicated: jax.sharding.Sharding  # the same on every device


def row_placement(devices) -> RowPlacement:
    """How a batch's arrays are put on ``devices`` (a sweep's chunks, a fit's rows): on the one device, or
    split along the rows over a 1-D mesh of several, XLA running each device's rows there."""
    mesh = jax.sharding.Mesh(np.array(devices), ("rows",))
    return RowPlacement(jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("rows")),
                        jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec()))
