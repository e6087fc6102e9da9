"""Which kind of device the rows are computed on, and how many rows one call takes (docs/devices.md).

A CPU and an accelerator (a GPU) want the same rows computed differently. A CPU runs a program's loops one
after another over memory that is also the host's: it is fastest over chunks of rows that fit its cache,
each stage of the exchange stored before the next reads it. An accelerator runs many rows at once from
memory of its own: it is fastest over chunks as large as its free memory allows, with XLA free to fuse the
stages, its results copied to the host while it computes the next chunk. Every batched path asks here
which of the two it is on (``on_cpu``) and how many rows to take at once (``chunk_rows``).

``path("accelerator")`` makes a CPU take the accelerator's path (and ``path("cpu")`` the reverse), so that
the accelerator's logic is exercised and tested where no accelerator is: both paths compute the same values.
The environment variable ``KS_JAX_PATH`` ("cpu" or "accelerator"), read at the first batch, sets the path for
the whole process (``KS_JAX_PATH=accelerator`` runs the test suite's batches the accelerator's way on a CPU).
"""

from __future__ import annotations

import contextlib
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


def _path_from_environment() -> str | None:
    """The path ``KS_JAX_PATH`` names, None where it is unset or empty; ValueError for any other value."""
    kind = os.environ.get("KS_JAX_PATH", "")
    if kind and kind not in PATHS:
        raise ValueError(f"KS_JAX_PATH = {kind!r}: must be 'cpu' or 'accelerator' (or unset: the default device's)")
    return kind or None


_forced: str | None = None  # the path of the innermost ``path`` block
_environment: list = []  # the path ``KS_JAX_PATH`` names, once read


def on_cpu() -> bool:
    """Whether the CPU's path applies: JAX's default backend is a CPU (unless ``path`` or ``KS_JAX_PATH`` says
    otherwise; a ValueError names a ``KS_JAX_PATH`` that is neither path). Both paths compute the same values;
    this only chooses how XLA is asked to compute them."""
    if _forced is not None:
        return _forced == "cpu"
    if not _environment:
        _environment.append(_path_from_environment())
    if _environment[0] is not None:
        return _environment[0] == "cpu"
    return jax.default_backend() == "cpu"


@contextlib.contextmanager
def path(kind: str):
    """Within the block, every batched path takes ``kind``'s way ("cpu" or "accelerator"), whatever the
    device. Where that changes the path, JAX's caches of traced programs are cleared on entry and exit,
    since a program traced for one path would otherwise be reused on the other."""
    global _forced
    if kind not in PATHS:
        raise ValueError(f"path = {kind!r}: must be 'cpu' or 'accelerator'")
    before, was_cpu = _forced, on_cpu()
    _forced = kind
    if on_cpu() != was_cpu:
        jax.clear_caches()
    try:
        yield
    finally:
        _forced = before
        if on_cpu() != was_cpu:
            jax.clear_caches()


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


def chunk_rows(bytes_per_row: int, device=None) -> int:
    """Rows per chunk for rows of ``bytes_per_row`` input and result bytes: ``CPU_CHUNK_ROWS`` on the CPU's
    path; on an accelerator's, the largest power of two whose working set (``WORKING_SET`` times the rows'
    bytes) takes at most ``MEMORY_SHARE`` of the device's free memory, within [``MIN_ROWS``, ``MAX_ROWS``]."""
    if on_cpu():
        return CPU_CHUNK_ROWS
    fits = int(MEMORY_SHARE * free_bytes(device)) // max(int(bytes_per_row) * WORKING_SET, 1)
    rows = 1 << max(fits, 1).bit_length() - 1
    return min(max(rows, MIN_ROWS), MAX_ROWS)


class RowPlacement(NamedTuple):
    rows: jax.sharding.Sharding  # arrays with the rows first: split along them
    replicated: jax.sharding.Sharding  # the same on every device


def row_placement(devices) -> RowPlacement:
    """How a batch's arrays are put on ``devices`` (a sweep's chunks, a fit's rows): on the one device, or
    split along the rows over a 1-D mesh of several, XLA running each device's rows there."""
    mesh = jax.sharding.Mesh(np.array(devices), ("rows",))
    return RowPlacement(jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("rows")),
                        jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec()))
