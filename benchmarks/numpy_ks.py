"""The KS exchange (docs/model.md, "The impulse exchange" and "Results") as plain vectorized NumPy,
for the benchmark.

Batch first: every input has a leading axis of N rows; vectors (N, 3), matrices (N, 3, 3).
Written the way one would write it in NumPy (np.cross, einsum, np.linalg.inv/solve over the
batch, boolean masks), computing the same results as ``ks_jax.exchange`` (exact cone, tau = 0),
including the per-row input checks. Not a test reference (tests/reference.py is); a baseline.
"""

from __future__ import annotations

import numpy as np

CODES = (10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20)


def rotation(yaw, pitch, roll):
    cz, sz, cy, sy, cx, sx = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    r = np.empty(yaw.shape + (3, 3))
    r[:, 0, 0], r[:, 0, 1], r[:, 0, 2] = cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx
    r[:, 1, 0], r[:, 1, 1], r[:, 1, 2] = sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx
    r[:, 2, 0], r[:, 2, 1], r[:, 2, 2] = -sy, cy * sx, cy * cx
    return r


def skew(r):
    z = np.zeros(r.shape[0])
    return np.stack([np.stack([z, -r[:, 2], r[:, 1]], -1), np.stack([r[:, 2], z, -r[:, 0]], -1),
                     np.stack([-r[:, 1], r[:, 0], z], -1)], -2)


def deg360(rad):
    d = np.mod(np.degrees(rad), 360.0)
    return np.where(d >= 360.0, d - 360.0, d)


def status(v1, s1, v2, s2, c):
    leaves = [*v1.values(), *s1.values(), *v2.values(), *s2.values(), *c.values()]
    n = v1["mass"].shape[0]
    finite = np.all([np.isfinite(x.reshape(n, -1)).all(-1) for x in leaves], axis=0)

    def inertia_ok(m):
        sym = np.abs(m - np.swapaxes(m, 1, 2)).max((1, 2)) <= 1e-6 * np.abs(m).max((1, 2))
        return sym & (m[:, 0, 0] > 0) & (m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0] > 0) & (np.linalg.det(m) > 0)

    box = lambda v: ((v["length"] > 0) & (v["width"] > 0) & (v["height"] > 0)  # noqa: E731
                     & (v["cg_to_front"] >= 0) & (v["cg_to_front"] <= v["length"])
                     & (v["cg_height"] >= 0) & (v["cg_height"] <= v["height"]))
    checks = [finite, v1["mass"] > 0, v2["mass"] > 0, inertia_ok(v1["inertia"]), inertia_ok(v2["inertia"]), box(v1),
              box(v2), (c["restitution"] >= -1) & (c["restitution"] <= 1), c["friction"] >= 0,
              np.einsum("ni,ni->n", c["normal"], c["normal"]) > 0, c["penetration_time"] >= 0]
    code = np.zeros(n, dtype=np.int32)
    for ok, bad in zip(reversed(checks), reversed(CODES)):
        code = np.where(ok, code, bad)
    return code


def exchange(v1, s1, v2, s2, c):
    """Dicts of (N, ...) arrays (fields of ks_jax.Vehicle/State/Contact; full (3, 3) inertias)
    -> dict of the results of docs/model.md (contact and per vehicle), NaN on invalid rows."""
    st = status(v1, s1, v2, s2, c)
    ok = st == 0
    with np.errstate(all="ignore"):
        n = c["normal"] / np.linalg.norm(c["normal"], axis=-1, keepdims=True)
        p = c["point"]
        rot1, rot2 = (rotation(s["yaw"], s["pitch"], s["roll"]) for s in (s1, s2))
        a1 = rot1 @ np.linalg.inv(np.where(ok[:, None, None], v1["inertia"], np.eye(3))) @ np.swapaxes(rot1, 1, 2)
        a2 = rot2 @ np.linalg.inv(np.where(ok[:, None, None], v2["inertia"], np.eye(3))) @ np.swapaxes(rot2, 1, 2)
        r1, r2 = p - s1["position"], p - s2["position"]
        u = ((s1["velocity"] + np.cross(s1["angular_velocity"], r1))
             - (s2["velocity"] + np.cross(s2["angular_velocity"], r2)))
        x1, x2 = skew(r1), skew(r2)
        K = ((1 / v1["mass"] + 1 / v2["mass"])[:, None, None] * np.eye(3) - x1 @ a1 @ x1 - x2 @ a2 @ x2)
        K = np.where(ok[:, None, None], K, np.eye(3))
        un = np.einsum("ni,ni->n", n, u)
        approaching = un < 0
        jc = -np.linalg.solve(K, u[..., None])[..., 0]
        nc = np.einsum("ni,ni->n", n, jc)
        tc = jc - nc[:, None] * n
        tn = np.linalg.norm(tc, axis=-1)
        a = c["friction"] * np.maximum(nc, 0.0)
        m = np.maximum(a, tn)
        d = n + np.where(m > 0, c["friction"] / np.where(m > 0, m, 1.0), 0.0)[:, None] * tc
        denom = np.einsum("ni,ni->n", n, np.einsum("nij,nj->ni", K, d))
        normal = np.where(approaching, -un / np.where(approaching, denom, 1.0), 0.0)
        j = ((1 + c["restitution"]) * normal)[:, None] * d
        sliding = approaching & (tn > a) & ok
        jmag = np.linalg.norm(j, axis=-1)
        out = {"status": np.where(ok & ~approaching, 1, st)}
        veh = []
        for sign, v, s, rot, ai, r, into in ((1, v1, s1, rot1, a1, r1, -n), (-1, v2, s2, rot2, a2, r2, n)):
            f = sign * j
            dv = f / v["mass"][:, None]
            dw = np.einsum("nij,nj->ni", ai, np.cross(r, f))
            va, wa = s["velocity"] + dv, s["angular_velocity"] + dw
            fb = np.einsum("nji,nj->ni", rot, f)
            pb = np.einsum("nji,nj->ni", rot, p - s["position"])
            db = np.einsum("nji,nj->ni", rot, into)
            lo = np.stack([v["cg_to_front"] - v["length"], -0.5 * v["width"], -v["cg_height"]], -1)
            hi = np.stack([v["cg_to_front"], 0.5 * v["width"], v["height"] - v["cg_height"]], -1)
            inside = np.all((pb >= lo) & (pb <= hi), -1)
            ex = np.where(db > 0, (hi - pb) / db, np.where(db < 0, (lo - pb) / db, np.inf))
            depth = ex.min(-1)
            pdof = deg360(np.arctan2(fb[:, 1], -fb[:, 0]))
            hour = np.mod(np.round(pdof / 30.0), 12.0)
            veh.append({"delta_v": dv, "delta_v_magnitude": jmag / v["mass"],
                        "delta_v_body": np.einsum("nji,nj->ni", rot, dv), "delta_yaw_rate": dw[:, 2],
                        "velocity_after": va, "speed_after": np.linalg.norm(va, axis=-1),
                        "course_after": deg360(np.arctan2(va[:, 1], va[:, 0])), "angular_velocity_after": wa,
                        "yaw_rate_after": wa[:, 2], "pdof": pdof, "pdof_clock": np.where(hour == 0, 12.0, hour),
                        "crush": np.where(inside & np.isfinite(depth), depth, 0.0), "_va": va, "_wa": wa})
        u_after = (veh[0]["_va"] + np.cross(veh[0]["_wa"], r1)) - (veh[1]["_va"] + np.cross(veh[1]["_wa"], r2))
        energy = -0.5 * np.einsum("ni,ni->n", j, u + u_after)
        total = veh[0]["crush"] + veh[1]["crush"]
        for vr, v in zip(veh, (v1, v2)):
            e_i = np.where(total > 0, energy * vr["crush"] / np.where(total > 0, total, 1.0), 0.0)
            vr["ees"] = np.where((total > 0) & (energy >= 0), np.sqrt(np.maximum(2 * e_i / v["mass"], 0.0)), np.nan)
            del vr["_va"], vr["_wa"]
        jn = np.einsum("ni,ni->n", n, j)
        out.update(point=p, normal=n, time=np.zeros_like(energy), impulse=j, impulse_magnitude=jmag, impulse_normal=jn,
                   impulse_tangential=np.linalg.norm(j - jn[:, None] * n, axis=-1),
                   impulse_azimuth=deg360(np.arctan2(j[:, 1], j[:, 0])),
                   impulse_elevation=np.degrees(np.arctan2(j[:, 2], np.hypot(j[:, 0], j[:, 1]))),
                   sliding=sliding, closing_velocity=u, separation_velocity=u_after, energy_loss=energy)
        for d in (out, *veh):
            for k, x in d.items():
                if k not in ("status", "sliding"):
                    d[k] = np.where(ok.reshape((-1,) + (1,) * (x.ndim - 1)), x, np.nan)
    return out, veh
