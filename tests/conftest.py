"""The test run's set-up: float64 on, one compile cache shared by the run's workers, the random cases of
``reference.py``, the memory a worker gives back, and the order files are handed to the workers in.

The helpers the test files share are in ``kit.py`` and ``samples.py``: nothing imports conftest.
"""

from __future__ import annotations

import collections
import ctypes
import json
import os
import shutil
import tempfile
from pathlib import Path

# On a GPU, XLA takes 75% of the device's memory at a process's first use of it: the second test worker
# (pytest-xdist) would then fail to start. Each worker allocates what it uses instead.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax

# ks_jax.cli.main keeps compiled programs in ~/.cache/ks-jax unless told otherwise; the tests that call
# it write nothing there (tests/test_compilation.py runs the command line with a cache of its own)
os.environ["KS_JAX_CACHE"] = "off"

jax.config.update("jax_enable_x64", True)

# Compilation is most of the suite's run time, and the workers of one run (pytest-xdist) build many of
# the same programs: they share one persistent compile cache, made for the run by the first process
# that loads this file (the controller, before it starts the workers, which inherit the variable) and
# deleted when that process ends. JAX keys each entry by the program, the compile options and its own
# version, so a loaded program is the one a compile would give. The library's programs compile with the
# settings users get: XLA's defaults, or ``ks_jax.compilation.QUICK_CPU`` where the library chooses it; a
# test's own wrappers and reference programs with the quick settings (``samples.reference_jit``).
_OWN_CACHE = "KS_JAX_TEST_COMPILE_CACHE" not in os.environ
if _OWN_CACHE:
    os.environ["KS_JAX_TEST_COMPILE_CACHE"] = tempfile.mkdtemp(prefix="ks-jax-test-xla-")
jax.config.update("jax_compilation_cache_dir", os.environ["KS_JAX_TEST_COMPILE_CACHE"])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


def pytest_unconfigure(config):
    if _OWN_CACHE:
        shutil.rmtree(os.environ.pop("KS_JAX_TEST_COMPILE_CACHE"), ignore_errors=True)


import numpy as np
import pytest

from ks_jax.compilation import free_programs
import reference as ref

@pytest.fixture(scope="session")
def random_cases():
    """300 random approaching 3D cases: 150 with principal inertias, 150 with full SPD tensors
    (two batches, since a vmapped batch needs one inertia shape)."""
    rng = np.random.default_rng(20240611)
    principal = [ref.random_case(rng, full_inertia=False) for _ in range(150)]
    full = [ref.random_case(rng, full_inertia=True) for _ in range(150)]
    return {"principal": principal, "full": full}


try:
    _TRIM = ctypes.CDLL("libc.so.6").malloc_trim  # glibc: give freed memory back to the system
except (OSError, AttributeError):
    _TRIM = None


# Within a file, its programs are freed after a test once the worker holds more than this: a file that solves many
# kinds of case (tests/command_matrix.py: every shipped case through every command) would otherwise hold all their
# programs at once.
FREE_PROGRAMS_ABOVE = 1536 * 2**20


@pytest.fixture(autouse=True)
def _return_freed_memory():
    """XLA frees what a compile allocated, but the C library keeps it in this process: after each test it is
    given back, so that a worker's memory is that of one test's programs, not the sum of all of them. Above
    ``FREE_PROGRAMS_ABOVE`` the test's programs are freed too (the run's compile cache keeps them on disk)."""
    yield
    resident = _resident_bytes()
    if resident is not None and resident > FREE_PROGRAMS_ABOVE:
        free_programs()
    if _TRIM is not None:
        _TRIM(0)


# A worker keeps its compiled and traced programs from one test file to the next while it holds less than this:
# the next file then runs the programs it shares with earlier ones (the conftest entry points, the library's
# solve, ...) without tracing, lowering and loading them again. Above it, they are freed.
# bytes of resident memory between two files (a worker peaked at ~2 GiB freeing every file)
KEEP_PROGRAMS_BELOW = 1280 * 2**20


def _resident_bytes():
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None  # not Linux: free every file's programs


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_programs():
    """A test file's compiled programs are freed when it ends (the run's compile cache keeps them on disk) once the
    worker's memory has reached ``KEEP_PROGRAMS_BELOW``."""
    yield
    if _TRIM is not None:
        _TRIM(0)
    resident = _resident_bytes()
    if resident is None or resident > KEEP_PROGRAMS_BELOW:
        free_programs()
        if _TRIM is not None:
            _TRIM(0)


# The longest files are handed to the test workers first: with ``--dist loadfile`` a worker takes a whole file,
# and a long one started last would leave the other worker idle for a minute at the end of the run. How long each
# took is measured (``durations.json``: wall seconds in a profiled run, written by ``benchmarks/suite_profile.py``);
# a file not measured yet counts 2 s for each of its slow tests (the ``slow`` mark's own threshold), so that it
# still finds a place near where it belongs.
DURATIONS = json.loads((Path(__file__).parent / "durations.json").read_text())


def pytest_collection_modifyitems(config, items):
    slow = collections.Counter(item.nodeid.split("::")[0] for item in items if item.get_closest_marker("slow"))

    def seconds(item):
        path = item.nodeid.split("::")[0]
        return DURATIONS.get(path, 2.0 * slow[path])

    items.sort(key=lambda item: -seconds(item))  # stable: a file's tests keep their order
