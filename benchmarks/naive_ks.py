"""The KS exchange (docs/model.md, "The impulse exchange" and "Results") as a first, naive JAX kernel,
for the benchmark.

One row at a time, written the way one would first write it in JAX: ``jnp.linalg.inv`` of the
inertia, 3x3 matrix products, ``jnp.cross``, the stick impulse by ``jnp.linalg.solve``, norms and
``jnp.arctan2`` as they come; batched by ``jax.jit(jax.vmap(exchange))``, which turns the inverse and
the solve into batched LU factorizations (one determinant, one inverse and one solve per batch, each
waiting for the one before). It computes what ``numpy_ks.exchange`` computes (the same
equations, the same per-row input checks, NaN in the results of an invalid row): the baseline that
benchmarks/bench_naive.py measures. Not a test reference (tests/reference.py is); a baseline.

Inputs: the per-row dicts of ``numpy_ks`` (fields of ks_jax.Vehicle/State/Contact, full (3, 3)
inertias); under ``jax.vmap`` with the batch first, the batch-first dicts themselves.
"""

from __future__ import annotations

import jax.numpy as jnp

CODES = (10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20)


def rotation(yaw, pitch, roll):
    cz, sz, cy, sy, cx, sx = jnp.cos(yaw), jnp.sin(yaw), jnp.cos(pitch), jnp.sin(pitch), jnp.cos(roll), jnp.sin(roll)
    return jnp.array([[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
                      [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
                      [-sy, cy * sx, cy * cx]])


def skew(r):
    return jnp.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def deg360(rad):
    return jnp.mod(jnp.degrees(rad), 360.0)


def status(v1, s1, v2, s2, c):
    leaves = [*v1.values(), *s1.values(), *v2.values(), *s2.values(), *c.values()]
    finite = jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in leaves]))

    # both inertias in one batched determinant (see ``exchange``)
    dets = jnp.linalg.det(jnp.stack([v1["inertia"], v2["inertia"]]))

    def inertia_ok(m, det):
        sym = jnp.max(jnp.abs(m - m.T)) <= 1e-6 * jnp.max(jnp.abs(m))
        return sym & (m[0, 0] > 0) & (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0] > 0) & (det > 0)

    box = lambda v: ((v["length"] > 0) & (v["width"] > 0) & (v["height"] > 0)  # noqa: E731
                     & (v["cg_to_front"] >= 0) & (v["cg_to_front"] <= v["length"])
                     & (v["cg_height"] >= 0) & (v["cg_height"] <= v["height"]))
    checks = [finite, v1["mass"] > 0, v2["mass"] > 0, inertia_ok(v1["inertia"], dets[0]),
              inertia_ok(v2["inertia"], dets[1]), box(v1), box(v2), (c["restitution"] >= -1) & (c["restitution"] <= 1),
              c["friction"] >= 0, jnp.dot(c["normal"], c["normal"]) > 0, c["penetration_time"] >= 0]
    code = jnp.int32(0)
    for ok, bad in zip(reversed(checks), reversed(CODES)):
        code = jnp.where(ok, code, bad)
    return code


def exchange(v1, s1, v2, s2, c):
    """One row: dicts of per-row arrays -> (contact results, [vehicle 1 results, vehicle 2 results])."""
    st = status(v1, s1, v2, s2, c)
    ok = st == 0
    n = c["normal"] / jnp.linalg.norm(c["normal"])
    p = c["point"]
    rot1, rot2 = (rotation(s["yaw"], s["pitch"], s["roll"]) for s in (s1, s2))
    # both inertias inverted in one call: XLA runs independent calls at once, and two batched LAPACK
    # calls at once never returned on the 2-core benchmark machine (bench_naive.py)
    inv1, inv2 = jnp.linalg.inv(jnp.where(ok, jnp.stack([v1["inertia"], v2["inertia"]]), jnp.eye(3)))
    a1 = rot1 @ inv1 @ rot1.T
    a2 = rot2 @ inv2 @ rot2.T
    r1, r2 = p - s1["position"], p - s2["position"]
    u = ((s1["velocity"] + jnp.cross(s1["angular_velocity"], r1))
         - (s2["velocity"] + jnp.cross(s2["angular_velocity"], r2)))
    x1, x2 = skew(r1), skew(r2)
    K = (1 / v1["mass"] + 1 / v2["mass"]) * jnp.eye(3) - x1 @ a1 @ x1 - x2 @ a2 @ x2
    K = jnp.where(ok, K, jnp.eye(3))
    un = jnp.dot(n, u)
    approaching = un < 0
    jc = -jnp.linalg.solve(K, u)
    nc = jnp.dot(n, jc)
    tc = jc - nc * n
    tn = jnp.linalg.norm(tc)
    a = c["friction"] * jnp.maximum(nc, 0.0)
    m = jnp.maximum(a, tn)
    d = n + jnp.where(m > 0, c["friction"] / jnp.where(m > 0, m, 1.0), 0.0) * tc
    denom = jnp.dot(n, K @ d)
    normal = jnp.where(approaching, -un / jnp.where(approaching, denom, 1.0), 0.0)
    j = (1 + c["restitution"]) * normal * d
    sliding = approaching & (tn > a) & ok
    jmag = jnp.linalg.norm(j)
    veh = []
    for sign, v, s, rot, ai, r, into in ((1, v1, s1, rot1, a1, r1, -n), (-1, v2, s2, rot2, a2, r2, n)):
        f = sign * j
        dv = f / v["mass"]
        dw = ai @ jnp.cross(r, f)
        va, wa = s["velocity"] + dv, s["angular_velocity"] + dw
        fb, pb, db = rot.T @ f, rot.T @ (p - s["position"]), rot.T @ into
        lo = jnp.array([v["cg_to_front"] - v["length"], -0.5 * v["width"], -v["cg_height"]])
        hi = jnp.array([v["cg_to_front"], 0.5 * v["width"], v["height"] - v["cg_height"]])
        inside = jnp.all((pb >= lo) & (pb <= hi))
        ex = jnp.where(db > 0, (hi - pb) / db, jnp.where(db < 0, (lo - pb) / db, jnp.inf))
        depth = jnp.min(ex)
        pdof = deg360(jnp.arctan2(fb[1], -fb[0]))
        hour = jnp.mod(jnp.round(pdof / 30.0), 12.0)
        veh.append({"delta_v": dv, "delta_v_magnitude": jmag / v["mass"], "delta_v_body": rot.T @ dv,
                    "delta_yaw_rate": dw[2], "velocity_after": va, "speed_after": jnp.linalg.norm(va),
                    "course_after": deg360(jnp.arctan2(va[1], va[0])), "angular_velocity_after": wa,
                    "yaw_rate_after": wa[2], "pdof": pdof, "pdof_clock": jnp.where(hour == 0, 12.0, hour),
                    "crush": jnp.where(inside & jnp.isfinite(depth), depth, 0.0), "_va": va, "_wa": wa})
    u_after = (veh[0]["_va"] + jnp.cross(veh[0]["_wa"], r1)) - (veh[1]["_va"] + jnp.cross(veh[1]["_wa"], r2))
    energy = -0.5 * jnp.dot(j, u + u_after)
    total = veh[0]["crush"] + veh[1]["crush"]
    for vr, v in zip(veh, (v1, v2)):
        e_i = jnp.where(total > 0, energy * vr["crush"] / jnp.where(total > 0, total, 1.0), 0.0)
        vr["ees"] = jnp.where((total > 0) & (energy >= 0), jnp.sqrt(jnp.maximum(2 * e_i / v["mass"], 0.0)), jnp.nan)
        del vr["_va"], vr["_wa"]
    jn = jnp.dot(n, j)
    out = {"status": jnp.where(ok & ~approaching, 1, st), "point": p, "normal": n, "time": jnp.zeros_like(energy),
           "impulse": j, "impulse_magnitude": jmag, "impulse_normal": jn,
           "impulse_tangential": jnp.linalg.norm(j - jn * n), "impulse_azimuth": deg360(jnp.arctan2(j[1], j[0])),
           "impulse_elevation": jnp.degrees(jnp.arctan2(j[2], jnp.hypot(j[0], j[1]))), "sliding": sliding,
           "closing_velocity": u, "separation_velocity": u_after, "energy_loss": energy}
    for dct in (out, *veh):
        for k, x in dct.items():
            if k not in ("status", "sliding"):
                dct[k] = jnp.where(ok, x, jnp.nan)
    return out, veh
