"""Shared test set-up: float64 on, the jitted entry points (compiled once per session), and
conversions between the NumPy case dicts of ``reference.py`` and ks_jax pytrees.

Tests get everything through the ``kit`` fixture so that nothing imports conftest.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
import types

# On a GPU, XLA takes 75% of the device's memory at a process's first use of it: the second test worker
# (pytest-xdist) would then fail to start. Each worker allocates what it uses instead.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax  # noqa: E402

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


import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import ks_jax  # noqa: E402
from ks_jax.compilation import free_programs  # noqa: E402
from ks_jax.model import types as kt  # noqa: E402
import reference as ref  # noqa: E402
from samples import reference_jit  # noqa: E402

CONTACT_RESULTS = ks_jax.ContactResult._fields
VEHICLE_RESULTS = ks_jax.VehicleResult._fields


def _leaf(values, dtype):
    return jnp.asarray(np.asarray(values, dtype=dtype))


def inputs(cases, dtype=np.float64):
    """Case dict (or a list of them: stacked on a leading batch axis) -> the five pytrees
    ``(vehicle1, state1, vehicle2, state2, contact)`` that ``ks_jax.exchange`` takes."""
    batch = isinstance(cases, (list, tuple))
    cs = list(cases) if batch else [cases]

    def col(get):
        vals = [get(c) for c in cs]
        return _leaf(vals if batch else vals[0], dtype)

    out = []
    for i in range(2):
        out.append(ks_jax.Vehicle(*(col(lambda c, k=k: c["vehicles"][i][k]) for k in ref.VEHICLE_INPUTS)))
        out.append(ks_jax.State(*(col(lambda c, k=k: c["vehicles"][i][k]) for k in ref.STATE_INPUTS)))
    contact = ks_jax.Contact(*(col(lambda c, k=k: c["contact"][k]) for k in ref.CONTACT_INPUTS),
                             col(lambda c: c["contact"].get("penetration_time", 0.0)))
    return (out[0], out[1], out[2], out[3], contact)


def reference_batch(cases):
    """reference.solve over a list of cases, stacked like the engine's batched results."""
    sols = [ref.solve(c) for c in cases]

    def stack(get):
        return np.array([get(s) for s in sols])

    con = {f: stack(lambda s, f=f: s["contact"][f]) for f in CONTACT_RESULTS}
    veh = [{f: stack(lambda s, f=f, i=i: s["vehicles"][i][f]) for f in VEHICLE_RESULTS} for i in range(2)]
    return {"contact": con, "vehicles": veh, "solutions": sols}


def engine_dict(result):
    """ExchangeResult -> {"contact": {field: np.ndarray}, "vehicles": [{...}, {...}]}."""
    con = {f: np.asarray(getattr(result.contact, f)) for f in CONTACT_RESULTS}
    veh = [{f: np.asarray(getattr(v, f)) for f in VEHICLE_RESULTS} for v in result.vehicles]
    return {"contact": con, "vehicles": veh}


RTOL_FLOAT32 = 5e-5  # float32 vs float64, relative to each field's natural scale (measured worst 4.7e-6)

TRACES = {"single": 0, "batch": 0, "grad": 0}  # Python side effect: counts (re)traces


def _single(v1, s1, v2, s2, c):
    TRACES["single"] += 1
    return ks_jax.exchange(v1, s1, v2, s2, c)


def _batch_row(v1, s1, v2, s2, c, smoothing):
    return ks_jax.exchange(v1, s1, v2, s2, c, smoothing=smoothing)


def _batch(v1, s1, v2, s2, c, smoothing):
    TRACES["batch"] += 1
    return jax.vmap(_batch_row, in_axes=(0, 0, 0, 0, 0, None))(v1, s1, v2, s2, c, smoothing)


# Scalar outputs that the gradient tests differentiate: (name, path, length).
OUTPUTS = (
    ("impulse", ("contact", "impulse"), 3),
    ("energy_loss", ("contact", "energy_loss"), 1),
    ("separation_velocity", ("contact", "separation_velocity"), 3),
    ("impulse_normal", ("contact", "impulse_normal"), 1),
    ("impulse_tangential", ("contact", "impulse_tangential"), 1),
    ("delta_v_1", (0, "delta_v"), 3),
    ("delta_v_2", (1, "delta_v"), 3),
    ("delta_v_body_1", (0, "delta_v_body"), 3),
    ("angular_velocity_after_1", (0, "angular_velocity_after"), 3),
    ("angular_velocity_after_2", (1, "angular_velocity_after"), 3),
    ("delta_v_magnitude_1", (0, "delta_v_magnitude"), 1),
    ("delta_v_magnitude_2", (1, "delta_v_magnitude"), 1),
    ("crush_1", (0, "crush"), 1),
    ("crush_2", (1, "crush"), 1),
    ("ees_1", (0, "ees"), 1),
    ("ees_2", (1, "ees"), 1),
)
OUTPUT_SLICES = {}
_k = 0
for _name, _path, _len in OUTPUTS:
    OUTPUT_SLICES[_name] = slice(_k, _k + _len)
    _k += _len
N_OUTPUTS = _k


def output_vector(result):
    """ExchangeResult -> (N_OUTPUTS,) the scalars of ``OUTPUTS``, concatenated."""
    parts = []
    for _, (where, field), _ in OUTPUTS:
        tree = result.contact if where == "contact" else result.vehicles[where]
        parts.append(jnp.reshape(getattr(tree, field), (-1,)))
    return jnp.concatenate(parts)


def _weighted(args, weights, smoothing):
    out = output_vector(ks_jax.exchange(*args, smoothing=smoothing))
    # a zero weight ignores its output even where that output is NaN (EES with no crush)
    return jnp.sum(jnp.where(weights != 0, weights * jnp.where(weights != 0, out, 0.0), 0.0))


def _grad(args, weights, smoothing):
    TRACES["grad"] += 1
    return jax.vmap(jax.value_and_grad(_weighted))(args, weights, smoothing)


# The jitted entry points, shared by every test file and compiled once per session for each
# inertia shape and dtype: batches are padded to a fixed number of rows, and ``smoothing`` is
# a traced argument (tau = 0 takes the exact branch; test_transforms checks that it equals the
# static ``smoothing=0.0`` path bit for bit).
EXCHANGE = jax.jit(_single)
BATCH_JIT = jax.jit(_batch)
# the gradients, checked against central differences and second formulations, with the quick settings of
# ``tests/samples.reference_jit``: XLA's settings change the rounding, not the derivative that is traced,
# and the exchange's gradient program is the largest the tests compile
GRAD_JIT = reference_jit(_grad)
BATCH_ROWS = 160
GRAD_ROWS = 128


def _chunked(fn, rows, batched, *rest):
    """Run ``fn`` over a batched pytree in chunks of exactly ``rows`` rows (padding the last by
    repeating its first row), so that every call has the same shape: one compilation."""
    leaves, treedef = jax.tree_util.tree_flatten(batched)
    leaves = [np.asarray(x) for x in leaves]
    total = leaves[0].shape[0]
    outs = []
    for start in range(0, total, rows):
        part = [x[start:start + rows] for x in leaves]
        k = part[0].shape[0]
        if k < rows:
            part = [np.concatenate([x, np.repeat(x[:1], rows - k, axis=0)]) for x in part]
        out = fn(jax.tree_util.tree_unflatten(treedef, [jnp.asarray(x) for x in part]), *rest)
        outs.append(jax.tree_util.tree_map(lambda y, k=k: np.asarray(y)[:k], out))
    return jax.tree_util.tree_map(lambda *ys: np.concatenate(ys), *outs)


def batch_exchange(args, smoothing=0.0):
    """The engine over a batched tuple of input pytrees, as a (NumPy) ExchangeResult."""
    return _chunked(lambda a, tau: BATCH_JIT(*a, tau), BATCH_ROWS, args, smoothing)


def value_and_grad(args, weights, smoothing):
    """Per row: (sum_k weights_k * output_k, its gradient pytree w.r.t. every input leaf).
    ``args`` batched input pytrees, ``weights`` (B, N_OUTPUTS), ``smoothing`` (B,)."""
    smoothing = np.broadcast_to(np.asarray(smoothing, dtype=float), (np.shape(weights)[0],))
    return _chunked(lambda t, _: GRAD_JIT(*t), GRAD_ROWS, (args, np.asarray(weights), smoothing), None)


def solve(cases, smoothing=0.0, dtype=np.float64):
    """Engine results for a case (jitted single solve, exact static smoothing = 0) or a list of
    cases (jitted batch), as NumPy dicts (see ``engine_dict``)."""
    if isinstance(cases, (list, tuple)):
        return engine_dict(batch_exchange(inputs(cases, dtype), smoothing))
    assert smoothing == 0.0
    return engine_dict(EXCHANGE(*inputs(cases, dtype)))


def scales(refb):
    """Per-row magnitudes that make every result field's tolerance relative (shape (B,)).

    impulse-like fields: |J|; closing/separation velocities: |u|; energy: the total kinetic
    energy before; angles: a full turn; velocities: |v| + |dv|; crush: the box size."""
    con = refb["contact"]
    sols = refb["solutions"]
    j = np.linalg.norm(con["impulse"], axis=-1)
    u = np.linalg.norm(con["closing_velocity"], axis=-1)
    ke = np.array([s["_"].get("ke_before", np.nan) for s in sols])
    return dict(j=j, u=u, ke=ke)


def assert_matches(eng, refb, rtol, cases, fields=None):
    """Every section-4 field of the engine equals the reference within ``rtol`` relative to the
    natural scale of that field (``scales``); exact for booleans, codes and clock hours."""
    sc = scales(refb)
    con_e, con_r = eng["contact"], refb["contact"]

    def close(name, a, b, scale, periodic=False):
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        scale = np.asarray(scale, dtype=float)
        while scale.ndim < b.ndim:
            scale = scale[..., None]
        both_nan = np.isnan(a) & np.isnan(b)
        diff = (a - b + 180.0) % 360.0 - 180.0 if periodic else a - b
        err = np.where(both_nan, 0.0, np.abs(diff))
        bad = ~(err <= rtol * scale)
        if np.any(bad):
            idx = np.argwhere(bad)[0]
            raise AssertionError(
                f"{name}: {int(bad.sum())} entries differ beyond rtol={rtol} of scale; first at {tuple(idx)}: "
                f"engine {a[tuple(idx)]!r} vs reference {b[tuple(idx)]!r} (scale {np.broadcast_to(scale, b.shape)[tuple(idx)]!r})")

    def angle(name, a, b):  # degrees, compared modulo 360, relative to a full turn
        close(name, a, b, 360.0 * np.ones(np.shape(b)), periodic=True)

    def want(name):
        return fields is None or name in fields

    j, u, ke = sc["j"], sc["u"], sc["ke"]
    status_codes = np.array([_status_code(s) for s in con_r["status"]])
    np.testing.assert_array_equal(con_e["status"], status_codes, err_msg="status")
    np.testing.assert_array_equal(con_e["sliding"], con_r["sliding"], err_msg="sliding")
    for name, scale in (("point", np.linalg.norm(con_r["point"], axis=-1)), ("normal", 1.0), ("time", 1.0),
                        ("impulse", j), ("impulse_magnitude", j), ("impulse_normal", j),
                        ("impulse_tangential", j), ("closing_velocity", u), ("separation_velocity", u),
                        ("energy_loss", ke)):
        if want(name):
            close(name, con_e[name], con_r[name], scale)
    for name in ("impulse_azimuth", "impulse_elevation"):
        if want(name):
            angle(name, con_e[name], con_r[name])
    for i in range(2):
        ve, vr = eng["vehicles"][i], refb["vehicles"][i]
        m = np.array([c["vehicles"][i]["mass"] for c in cases])
        size = np.array([c["vehicles"][i]["length"] for c in cases])
        speed0 = np.linalg.norm([c["vehicles"][i]["velocity"] for c in cases], axis=-1)
        w0 = np.linalg.norm([c["vehicles"][i]["angular_velocity"] for c in cases], axis=-1)
        dw = np.linalg.norm(vr["angular_velocity_after"] - np.array([c["vehicles"][i]["angular_velocity"]
                                                                       for c in cases]), axis=-1)
        for name, scale in (("delta_v", j / m), ("delta_v_magnitude", j / m), ("delta_v_body", j / m),
                            ("velocity_after", speed0 + j / m), ("speed_after", speed0 + j / m),
                            ("delta_yaw_rate", dw), ("angular_velocity_after", w0 + dw),
                            ("yaw_rate_after", w0 + dw), ("crush", size),
                            ("ees", np.sqrt(2 * np.abs(ke) / m))):
            if want(name):
                close(f"vehicles[{i}].{name}", ve[name], vr[name], scale)
        for name in ("course_after", "pdof"):
            if want(name):
                angle(f"vehicles[{i}].{name}", ve[name], vr[name])
        if want("pdof_clock"):
            np.testing.assert_array_equal(ve["pdof_clock"], vr["pdof_clock"], err_msg=f"vehicles[{i}].pdof_clock")


def _status_code(text):
    """The reference's status words -> the engine's status code (``ks_jax.model.types``)."""
    table = {
        "ok": kt.OK, "separating": kt.SEPARATING, "invalid: nonfinite": kt.INVALID_NONFINITE,
        "invalid: mass 1": kt.INVALID_MASS_1, "invalid: mass 2": kt.INVALID_MASS_2,
        "invalid: inertia 1": kt.INVALID_INERTIA_1, "invalid: inertia 2": kt.INVALID_INERTIA_2,
        "invalid: box 1": kt.INVALID_BOX_1, "invalid: box 2": kt.INVALID_BOX_2,
        "invalid: restitution": kt.INVALID_RESTITUTION, "invalid: friction": kt.INVALID_FRICTION,
        "invalid: normal": kt.INVALID_NORMAL,
    }
    return table[str(text)]


@pytest.fixture(scope="session")
def kit():
    """Helpers shared by the test files (see the module functions of the same names)."""
    return types.SimpleNamespace(
        inputs=inputs, solve=solve, reference_batch=reference_batch, engine_dict=engine_dict,
        assert_matches=assert_matches, status_code=_status_code, exchange=EXCHANGE,
        batch_exchange=batch_exchange, value_and_grad=value_and_grad, output_vector=output_vector,
        outputs=OUTPUTS, output_slices=OUTPUT_SLICES, n_outputs=N_OUTPUTS, traces=TRACES,
        jitted={"single": EXCHANGE, "batch": BATCH_JIT, "grad": GRAD_JIT},
        rtol_float32=RTOL_FLOAT32,
    )


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
# kinds of case (tests/test_matrix.py: every shipped case through every command) would otherwise hold all their
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
KEEP_PROGRAMS_BELOW = 1280 * 2**20  # bytes of resident memory between two files (a worker peaked at ~2 GiB freeing every file)


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


# The files that take longest (compiling is most of their time), handed to the test workers first: with
# ``--dist loadfile`` a worker takes a whole file, and one of these started last would leave the other
# worker idle for a minute at the end of the run.
LONGEST_FIRST = ("test_matrix.py", "test_notebooks.py", "fit/test_properties.py", "sweeps/test_sweep.py",
                 "fit/test_reconstruction.py", "batch/test_chunks.py", "model/test_automatic.py", "test_solve.py",
                 "plot/test_sweep_view.py", "model/test_fixed.py", "fit/test_posterior.py", "batch/test_loss.py",
                 "model/test_collision.py", "test_rest.py")


def pytest_collection_modifyitems(config, items):
    def rank(item):
        path = item.nodeid.split("::")[0]
        return next((k for k, name in enumerate(LONGEST_FIRST) if path.endswith(name)), len(LONGEST_FIRST))

    items.sort(key=rank)  # stable: the other files, and the tests within each file, keep their order
