"""Shared test set-up: float64 on, the jitted entry points (compiled once per session), and
conversions between the NumPy case dicts of ``reference.py`` and ks_jax pytrees.

Tests get everything through the ``kit`` fixture so that nothing imports conftest.
"""

from __future__ import annotations

import types

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import ks_jax  # noqa: E402
import reference as ref  # noqa: E402

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


def _exchange(v1, s1, v2, s2, c, smoothing):
    return ks_jax.exchange(v1, s1, v2, s2, c, smoothing=smoothing)


# One jitted single solve and one jitted batch solve, shared by every test file.
EXCHANGE = jax.jit(_exchange, static_argnums=5)
BATCH = jax.jit(jax.vmap(_exchange, in_axes=(0, 0, 0, 0, 0, None)), static_argnums=5)


def solve(cases, smoothing=0.0, dtype=np.float64):
    """Engine results for a case or a list of cases, as NumPy dicts (see ``engine_dict``)."""
    batch = isinstance(cases, (list, tuple))
    fn = BATCH if batch else EXCHANGE
    return engine_dict(fn(*inputs(cases, dtype), smoothing))


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

    def close(name, a, b, scale):
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        scale = np.asarray(scale, dtype=float)
        while scale.ndim < b.ndim:
            scale = scale[..., None]
        both_nan = np.isnan(a) & np.isnan(b)
        err = np.where(both_nan, 0.0, np.abs(a - b))
        bad = ~(err <= rtol * scale)
        if np.any(bad):
            idx = np.argwhere(bad)[0]
            raise AssertionError(
                f"{name}: {int(bad.sum())} entries differ beyond rtol={rtol} of scale; first at {tuple(idx)}: "
                f"engine {a[tuple(idx)]!r} vs reference {b[tuple(idx)]!r} (scale {np.broadcast_to(scale, b.shape)[tuple(idx)]!r})")

    def angle(name, a, b):
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        d = (a - b + 180.0) % 360.0 - 180.0
        close(name, np.where(np.isnan(a), np.nan, d), np.where(np.isnan(b), np.nan, 0.0), 360.0 * np.ones(b.shape))

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
    from ks_jax import types as t

    table = {
        "ok": t.OK, "separating": t.SEPARATING, "invalid: nonfinite": t.INVALID_NONFINITE,
        "invalid: mass 1": t.INVALID_MASS_1, "invalid: mass 2": t.INVALID_MASS_2,
        "invalid: inertia 1": t.INVALID_INERTIA_1, "invalid: inertia 2": t.INVALID_INERTIA_2,
        "invalid: box 1": t.INVALID_BOX_1, "invalid: box 2": t.INVALID_BOX_2,
        "invalid: restitution": t.INVALID_RESTITUTION, "invalid: friction": t.INVALID_FRICTION,
        "invalid: normal": t.INVALID_NORMAL,
    }
    return table[str(text)]


@pytest.fixture(scope="session")
def kit():
    """Helpers shared by the test files (see the module functions of the same names)."""
    return types.SimpleNamespace(
        inputs=inputs, solve=solve, reference_batch=reference_batch, engine_dict=engine_dict,
        assert_matches=assert_matches, status_code=_status_code, exchange=EXCHANGE, batch=BATCH,
        raw_exchange=_exchange,
    )


@pytest.fixture(scope="session")
def random_cases():
    """300 random approaching 3D cases: 150 with principal inertias, 150 with full SPD tensors
    (two batches, since a vmapped batch needs one inertia shape)."""
    rng = np.random.default_rng(20240611)
    principal = [ref.random_case(rng, full_inertia=False) for _ in range(150)]
    full = [ref.random_case(rng, full_inertia=True) for _ in range(150)]
    return {"principal": principal, "full": full}
