"""Helpers shared by the test files: float64 inputs from ``reference.py``'s case dicts, the jitted entry points
(compiled once per process), the reference's batched solutions, and comparisons of the engine against it.
Test files import it (``import kit``); tests/conftest.py sets up JAX (float64, the run's compile cache) before
any test file is imported."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import ks_jax
from ks_jax.model import types as kt
import reference as ref
from samples import reference_jit

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
exchange = jax.jit(_single)  # one exchange, jitted once per process
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
    return engine_dict(exchange(*inputs(cases, dtype)))


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
                f"engine {a[tuple(idx)]!r} vs reference {b[tuple(idx)]!r} "
                f"(scale {np.broadcast_to(scale, b.shape)[tuple(idx)]!r})")

    def angle(name, a, b):  # degrees, compared modulo 360, relative to a full turn
        close(name, a, b, 360.0 * np.ones(np.shape(b)), periodic=True)

    def want(name):
        return fields is None or name in fields

    j, u, ke = sc["j"], sc["u"], sc["ke"]
    status_codes = np.array([status_code(s) for s in con_r["status"]])
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


def status_code(text):
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


JITTED = {"single": exchange, "batch": BATCH_JIT, "grad": GRAD_JIT}
