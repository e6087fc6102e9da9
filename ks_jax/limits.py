"""Work refused before it starts because it would not fit in this machine's memory (a sweep's values, its kept
results, the rows of a fit): a message with the figure, rather than an allocation that fails part way; and what a
count of rows, starts or draws must be."""

from __future__ import annotations

import os

import numpy as np

from .case.errors import CaseError


def is_count(value, least: int) -> bool:
    """``value`` is a whole number (an int, not a bool, or a NumPy integer) >= ``least``: int() would have taken
    "3" or 2.5 (as 2) without a word."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= least


def is_fraction(value) -> bool:
    """``value`` is one real number strictly between 0 and 1 (not a bool, a string or an array)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and 0 < value < 1


def is_float_dtype(value) -> bool:
    """``value`` names float32 or float64, the dtypes ks-jax computes and stores in (not float16, an integer type
    or a string that names no dtype)."""
    try:
        return np.dtype(value) in (np.float32, np.float64)
    except TypeError:
        return False


def memory_bytes():
    """This machine's physical memory in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(nbytes, what, advice):
    """CaseError where ``what`` needs more bytes than the machine has."""
    memory = memory_bytes()
    if memory is not None and nbytes > memory:
        raise CaseError(f"{what} needs {nbytes / 2**30:.3g} GiB, more than this machine's {memory / 2**30:.3g} GiB: "
                        f"{advice}")
