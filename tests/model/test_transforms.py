"""JAX transformations and scene symmetries: jit(exchange) == exchange, vmap(exchange) ==
stacked single solves, no recompilation for new values, and results that rotate and translate
with the scene (docs/model.md, "The impulse exchange", cross-checks; section 8)."""

from __future__ import annotations

import importlib
import math
import os
import re

import jax
import numpy as np
import pytest

import ks_jax
from ks_jax.case import load_case
import reference as ref
from samples import reference_jit
import kit

RTOL_JIT = 1e-13  # jit vs eager, vmap vs single: the same arithmetic, fused differently
RTOL_COVARIANCE = 1e-10  # rotated / translated scene vs the original, relative to each field's scale
ANGLE_FIELDS = ("impulse_azimuth", "impulse_elevation", "course_after", "pdof")


def _as_np(tree):
    return jax.tree_util.tree_map(lambda x: np.asarray(x, dtype=float) if np.asarray(x).dtype != bool
                                  else np.asarray(x), tree)


def assert_trees_close(a, b, rtol, what=""):
    """Leaf by leaf, relative to the largest magnitude of that leaf (over all rows of a batch);
    NaN == NaN; booleans and codes exactly; angles (degrees) modulo 360, relative to a turn."""
    leaves_a, _ = jax.tree_util.tree_flatten_with_path(_as_np(a))
    leaves_b = jax.tree_util.tree_leaves(_as_np(b))
    assert len(leaves_a) == len(leaves_b)
    for (path, x), y in zip(leaves_a, leaves_b):
        name = jax.tree_util.keystr(path)
        assert x.shape == y.shape, name
        if x.dtype == bool or np.issubdtype(x.dtype, np.integer):
            np.testing.assert_array_equal(x, y, err_msg=f"{what}{name}")
            continue
        d = x - y
        if any(f in name for f in ANGLE_FIELDS):
            d = (d + 180.0) % 360.0 - 180.0
            scale = 360.0
        else:
            scale = np.nanmax(np.abs(y)) if np.any(np.isfinite(y)) else 1.0
        same_nan = np.isnan(x) == np.isnan(y)
        assert np.all(same_nan), f"{what}{name}: NaN pattern differs"
        err = np.nanmax(np.abs(d)) if np.any(np.isfinite(d)) else 0.0
        assert err <= rtol * max(scale, 1e-300), f"{what}{name}: {err} > {rtol} * {scale}"


# --------------------------------------------------------------------------- jit, vmap, retracing
@pytest.fixture(scope="module")
def few_cases(random_cases):
    return random_cases["principal"][:4] + random_cases["principal"][40:44]


@pytest.mark.slow
def test_jit_equals_eager(few_cases):
    for c in few_cases[:3]:
        args = kit.inputs(c)
        eager = ks_jax.exchange(*args)
        jitted = kit.exchange(*args)
        assert_trees_close(jitted, eager, RTOL_JIT, "jit vs eager: ")


@pytest.mark.slow
def test_eager_smooth_equals_jit_vmap_row(random_cases):
    """The static Python-float smoothing (eager) equals the traced one (jitted batch)."""
    c = random_cases["principal"][7]
    eager = ks_jax.exchange(*kit.inputs(c), smoothing=0.05)
    row = jax.tree_util.tree_map(lambda x: x[0], kit.batch_exchange(kit.inputs([c]), 0.05))
    assert_trees_close(row, eager, RTOL_JIT, "eager vs jit(vmap): ")


@pytest.mark.slow
def test_vmap_equals_stacked_single_calls(random_cases):
    cases = random_cases["principal"][:20]
    singles = [kit.exchange(*kit.inputs(c)) for c in cases]
    stacked = jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *singles)
    batched = kit.batch_exchange(kit.inputs(cases), 0.0)
    assert_trees_close(batched, stacked, RTOL_JIT, "vmap vs stacked singles: ")
    # the plain jax.vmap of the public function, too (no padding, no traced smoothing), jitted: one program
    # (run eagerly, each of its ~110 operations would compile a program of its own)
    plain = reference_jit(jax.vmap(ks_jax.exchange))(*kit.inputs(cases[:5]))
    assert_trees_close(plain, jax.tree_util.tree_map(lambda x: x[:5], stacked), RTOL_JIT, "jax.vmap: ")


@pytest.mark.slow
def test_no_recompilation_for_new_values(few_cases):
    kit.exchange(*kit.inputs(few_cases[0]))  # compiled (at most once) here or earlier
    kit.batch_exchange(kit.inputs(few_cases[:2]), 0.0)
    single, batch = kit.TRACES["single"], kit.TRACES["batch"]
    single_cache = kit.JITTED["single"]._cache_size()
    batch_cache = kit.JITTED["batch"]._cache_size()
    for c in few_cases[1:]:
        kit.exchange(*kit.inputs(c))
    for tau in (0.0, 0.02, 0.3):  # a new smoothing value is a new value, not a new program
        kit.batch_exchange(kit.inputs(few_cases[2:]), tau)
    assert kit.TRACES["single"] == single and kit.TRACES["batch"] == batch
    assert kit.JITTED["single"]._cache_size() == single_cache
    assert kit.JITTED["batch"]._cache_size() == batch_cache
    assert single >= 1 and batch >= 1  # the counters do count


def _program(text):
    """A compiled program's text without its source locations (which name the calling files)."""
    head, rest = text.split("\n", 1)
    if "StackFrames" in rest:
        rest = rest[rest.index("\n\n", rest.index("StackFrames")):]
    return (head + re.sub(r",? metadata=\{[^}]*\}", "", rest)).rstrip()


# the same operations compiled at LLVM level 0 with XLA's classic emitters and at XLA's defaults: rounding apart
# (absolute in SI for results that are rounding around 0, as the yaw rates of the seed chapter's inline crash)
RTOL_QUICK, ATOL_QUICK = 1e-12, 1e-12


@pytest.mark.slow
@pytest.mark.skipif(jax.default_backend() != "cpu", reason="XLA's CPU settings")
@pytest.mark.parametrize("name", ["seed_000_saturn_pontiac.json", "auto_seed_000.json", "rest_seed_000.json"])
def test_solve_compiles_with_the_quick_settings_and_gets_the_defaults_values(name):
    """``ks_jax.solve``'s program (a file's few cases) is compiled with ``ks_jax.compilation.QUICK_CPU``, not
    with XLA's defaults (another program), and give the values of the programs compiled at XLA's defaults:
    the seed chapter (explicit contact), its staging with automatic contact and its motion to rest, solved as a
    file of two cases (the case and the same one with the bullet car 3 mph faster), every result of every
    stage."""
    sv = importlib.import_module("ks_jax.solve.cases")  # the module of ks_jax.solve (the function)
    case = load_case(os.path.join(os.path.dirname(ks_jax.__file__), "cases", name))
    faster = ks_jax.set_input(case.inputs, "vehicles[1].speed", ks_jax.get_input(case.inputs, "vehicles[1].speed")
                              + 3 * ks_jax.units.MPH)
    inputs = ks_jax.case.as_arrays(jax.tree_util.tree_map(lambda *x: np.stack(x), case.inputs, faster))
    args = (inputs, case.auto_point, case.auto_normal, 0.0, False, case.motion)
    plain = sv._solve.plain._cache_size()
    quick = sv._solve(*args)  # what ks_jax.solve runs: the quick program, not the plain one
    assert sv._solve.plain._cache_size() == plain and sv._solve.quick._cache_size() >= 1
    defaults = sv._solve.plain(*args)
    named = jax.tree_util.tree_flatten_with_path(_as_np(quick))[0]
    for (path, x), y in zip(named, jax.tree_util.tree_leaves(_as_np(defaults))):
        name = jax.tree_util.keystr(path)
        if x.dtype == bool or np.issubdtype(x.dtype, np.integer):
            np.testing.assert_array_equal(x, y, err_msg=name)
        elif any(f in name for f in ANGLE_FIELDS):  # degrees, on the circle (NaN in the same places: unused slots)
            np.testing.assert_array_equal(np.isnan(x), np.isnan(y), err_msg=name)
            np.testing.assert_allclose(np.nan_to_num((x - y + 180.0) % 360.0 - 180.0), 0.0, atol=RTOL_QUICK * 360.0,
                                       err_msg=name)
        else:
            np.testing.assert_allclose(x, y, rtol=RTOL_QUICK, atol=ATOL_QUICK, equal_nan=True, err_msg=name)
    assert np.all(np.asarray(quick.contact.status) == 0)
    assert (quick.rest is not None) == (case.motion is not None)  # the motion to rest compared where there is one
    assert _program(sv._solve.quick.lower(*args).compile().as_text()) != \
        _program(sv._solve.plain.lower(*args).compile().as_text())  # another program


# --------------------------------------------------------------------------- scene symmetries
def _expected(base, q, shift, alpha_deg=None):
    """The base results as the transformed scene should give them: vectors rotated by q, the
    point also shifted; scalars and body-frame quantities unchanged; global azimuths + alpha
    (rotations about z only, else those are dropped)."""
    con = dict(base["contact"])
    for f in ("normal", "impulse", "closing_velocity", "separation_velocity"):
        con[f] = con[f] @ q.T
    con["point"] = con["point"] @ q.T + shift
    vehs = []
    for v in base["vehicles"]:
        v = dict(v)
        for f in ("delta_v", "velocity_after", "angular_velocity_after"):
            v[f] = v[f] @ q.T
        vehs.append(v)
    if alpha_deg is None:
        for f in ("impulse_azimuth", "impulse_elevation"):
            con.pop(f)
        for v in vehs:
            for f in ("course_after", "delta_yaw_rate", "yaw_rate_after"):
                v.pop(f)
    else:
        con["impulse_azimuth"] = (con["impulse_azimuth"] + alpha_deg) % 360.0
        for v in vehs:
            v["course_after"] = (v["course_after"] + alpha_deg) % 360.0
    return {"contact": con, "vehicles": vehs}


def _compare(got, want, rtol):
    for part_g, part_w, label in ((got["contact"], want["contact"], "contact"),
                                  (got["vehicles"][0], want["vehicles"][0], "vehicles[0]"),
                                  (got["vehicles"][1], want["vehicles"][1], "vehicles[1]")):
        assert_trees_close({k: part_g[k] for k in part_w}, part_w, rtol, f"{label}.")


@pytest.mark.parametrize("kind", ["principal", "full"])
def test_rotation_about_z_and_translation(random_cases, kind):
    rng = np.random.default_rng(21)
    cases = random_cases[kind]
    alpha = rng.uniform(-math.pi, math.pi)
    q = ref.rot_z(alpha)
    shift = rng.normal(0, 50, size=3)
    base = kit.solve(cases)
    moved = kit.solve([ref.transform(c, q, shift) for c in cases])
    for c in cases[:5]:  # about z, the orientation change is yaw + alpha alone
        m = ref.transform(c, q, shift)
        for a, b in zip(c["vehicles"], m["vehicles"]):
            dyaw = (b["yaw"] - a["yaw"] - alpha + math.pi) % (2 * math.pi) - math.pi
            assert abs(dyaw) < 1e-12 and b["pitch"] == pytest.approx(a["pitch"], abs=1e-12)
            assert b["roll"] == pytest.approx(a["roll"], abs=1e-12)
    _compare(moved, _expected(base, q, shift, math.degrees(alpha)), RTOL_COVARIANCE)
    # translation alone changes nothing but the point
    shifted = kit.solve([ref.transform(c, None, shift) for c in cases])
    _compare(shifted, _expected(base, np.eye(3), shift, 0.0), RTOL_COVARIANCE)


def _random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


@pytest.mark.parametrize("kind", ["principal", "full"])
def test_general_rotation_is_covariant(random_cases, kind):
    """A general 3D rotation of the whole scene (orientations become Q R, re-expressed as yaw,
    pitch, roll): impulse, delta-V, velocities and angular velocities rotate; energy, |J|, the
    normal/tangential split, body-frame delta-V, PDOF, crush and EES do not change."""
    rng = np.random.default_rng(22)
    cases = random_cases[kind]
    q = _random_rotation(rng)
    shift = rng.normal(0, 10, size=3)
    moved_cases = [ref.transform(c, q, shift) for c in cases]
    for c, m in zip(cases[:5], moved_cases[:5]):  # the re-expressed orientation is Q R
        for a, b in zip(c["vehicles"], m["vehicles"]):
            np.testing.assert_allclose(ref.rotation(b["yaw"], b["pitch"], b["roll"]),
                                       q @ ref.rotation(a["yaw"], a["pitch"], a["roll"]), atol=1e-14)
    base = kit.solve(cases)
    moved = kit.solve(moved_cases)
    _compare(moved, _expected(base, q, shift), RTOL_COVARIANCE)
