"""The host's work on a batch of fits: Python's cyclic garbage collector paused while it runs.

Checking a batch's cases, stacking their arrays, analysing their fits and building their results make many small
objects (tuples, lists, dicts of numbers and words), none of them in a cycle. Each such allocation counts toward
the collector's next collection, and its full collections walk every object alive, the caller's cases among them:
at 10^4 cases, three full collections were a quarter of a batch's host work (docs/performance.md). Paused, it
makes one collection of the young objects when it is running again, and nothing made is left uncollected: what
became cyclic garbage in the meantime is found by its next collection."""

from __future__ import annotations

import contextlib
import gc


@contextlib.contextmanager
def collector_paused():
    """Within the block (or the call of a function it decorates), Python's cyclic garbage collector paused; after,
    as it was. Nested pauses keep it paused until the outermost ends."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()
