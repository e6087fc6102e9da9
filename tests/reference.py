"""An independent plain-NumPy formulation of the KS impulse exchange (docs/model.md, "The impulse exchange").

This module is the test suite's second opinion. It never imports ``ks_jax``: it is written
from the equations of docs/model.md with the most literal tools NumPy offers (``np.linalg.solve``,
``np.linalg.inv``, explicit cross-product matrices, Python ``if`` branches), so that a mistake
in the engine's closed-form, branch-free kernel shows up as a disagreement.

Where the engine is clever, this module is plain:

* the friction-cone limit uses s* = min(1, mu N_c / |T_c|) and d(s) = n + s T_c / N_c literally,
  with the N_c <= 0 branch written out (engine: one max() formula);
* the energy loss is the kinetic energy before minus after, translation and rotation of both
  bodies, with world inertia R I_body R^T (engine: -J.(u + u')/2);
* the crush is found by bisection along the ray (engine: slab intersection);
* angles use ``np.arctan2``/``np.arcsin`` in degrees and Python's modulo.

A case is a plain dict of NumPy values in SI units (see ``random_case``)::

    {"vehicles": [veh, veh], "contact": {"point", "normal", "restitution", "friction"}}
    veh = {"mass", "inertia" ((3,) principal or (3, 3) body tensor), "length", "width",
           "height", "cg_to_front", "cg_height", "position" (3,), "velocity" (3,),
           "yaw", "pitch", "roll", "angular_velocity" (3,)}

``solve(case)`` returns the section-4 results under the same names, as a dict
``{"contact": {...}, "vehicles": [{...}, {...}]}`` plus a few internals under ``"_"``.
"""

from __future__ import annotations

import copy
import math

import numpy as np

VEHICLE_INPUTS = ("mass", "inertia", "length", "width", "height", "cg_to_front", "cg_height")
STATE_INPUTS = ("position", "velocity", "yaw", "pitch", "roll", "angular_velocity")
CONTACT_INPUTS = ("point", "normal", "restitution", "friction")


# --------------------------------------------------------------------------- geometry
def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation(yaw, pitch, roll):
    """R = Rz(yaw) Ry(pitch) Rx(roll), body (ISO 8855) -> global (docs/model.md, "Units and frames")."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def euler_from_rotation(m):
    """(yaw, pitch, roll) with rotation(yaw, pitch, roll) == m (|pitch| < 90 deg)."""
    yaw = math.atan2(m[1, 0], m[0, 0])
    pitch = -math.asin(max(-1.0, min(1.0, m[2, 0])))
    roll = math.atan2(m[2, 1], m[2, 2])
    return yaw, pitch, roll


def skew(a):
    """[a]x, the matrix with [a]x b = a x b."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def body_inertia(inertia):
    inertia = np.asarray(inertia, dtype=float)
    return np.diag(inertia) if inertia.ndim == 1 else inertia


def world_inertia(veh):
    rot = rotation(veh["yaw"], veh["pitch"], veh["roll"])
    return rot @ body_inertia(veh["inertia"]) @ rot.T


def wrap_degrees(rad):
    """Radians -> degrees in [0, 360)."""
    d = math.degrees(rad) % 360.0
    return 0.0 if d >= 360.0 else d


def direction_degrees(y, x):
    """atan2(y, x) in degrees in [0, 360); 0 for the zero vector (J = 0 at a separating contact:
    the direction is undefined and reported as 0)."""
    if x == 0 and y == 0:
        return 0.0
    return wrap_degrees(math.atan2(y, x))


def box_bounds(veh):
    lo = np.array([veh["cg_to_front"] - veh["length"], -0.5 * veh["width"], -veh["cg_height"]])
    hi = np.array([veh["cg_to_front"], 0.5 * veh["width"], veh["height"] - veh["cg_height"]])
    return lo, hi


def crush(veh, point, direction):
    """Distance from ``point`` along ``direction`` (global, unit) until it leaves the vehicle's
    bounding box, 0 if the point is outside (docs/model.md, "Results"). Found by bisection on the
    'inside' predicate (the box is convex, so the ray is inside on one interval [0, t_exit])."""
    rot = rotation(veh["yaw"], veh["pitch"], veh["roll"])
    lo, hi = box_bounds(veh)

    def inside(t):
        q = rot.T @ (np.asarray(point) + t * np.asarray(direction) - np.asarray(veh["position"]))
        return bool(np.all(q >= lo) and np.all(q <= hi))

    if not inside(0.0):
        return 0.0
    a, b = 0.0, 1.01 * float(np.linalg.norm(hi - lo))  # inside at a, outside at b
    for _ in range(200):
        mid = 0.5 * (a + b)
        if mid <= a or mid >= b:
            break
        if inside(mid):
            a = mid
        else:
            b = mid
    return 0.5 * (a + b)


# --------------------------------------------------------------------------- validity
def input_status(case):
    """'ok' or 'invalid: <field>' for the first broken rule (the engine's order)."""
    v1, v2 = case["vehicles"]
    c = case["contact"]
    values = [np.asarray(x, dtype=float) for v in (v1, v2) for x in v.values()]
    values += [np.asarray(c[k], dtype=float) for k in CONTACT_INPUTS]
    if not all(np.all(np.isfinite(x)) for x in values):
        return "invalid: nonfinite"
    for i, v in enumerate((v1, v2)):
        if not v["mass"] > 0:
            return f"invalid: mass {i + 1}"
    for i, v in enumerate((v1, v2)):
        ib = body_inertia(v["inertia"])
        if not (np.allclose(ib, ib.T, rtol=0, atol=1e-9 * np.abs(ib).max()) and np.all(np.linalg.eigvalsh(ib) > 0)):
            return f"invalid: inertia {i + 1}"
    for i, v in enumerate((v1, v2)):
        if not (v["length"] > 0 and v["width"] > 0 and v["height"] > 0 and 0 <= v["cg_to_front"] <= v["length"]
                and 0 <= v["cg_height"] <= v["height"]):  # the CG inside its box
            return f"invalid: box {i + 1}"
    if not -1.0 <= c["restitution"] <= 1.0:
        return "invalid: restitution"
    if not c["friction"] >= 0:
        return "invalid: friction"
    if not np.linalg.norm(c["normal"]) > 0:
        return "invalid: normal"
    return "ok"


# --------------------------------------------------------------------------- the model
def kinetic_energy(veh, velocity, angular_velocity):
    """Translation + rotation, 1/2 m v.v + 1/2 w.I w with the world inertia."""
    v = np.asarray(velocity)
    w = np.asarray(angular_velocity)
    return 0.5 * veh["mass"] * v @ v + 0.5 * w @ world_inertia(veh) @ w


def stick_split(case):
    """(u, n, K, J_c, N_c, T_c) of docs/model.md, "The impulse exchange", steps 1, 2 and 4."""
    v1, v2 = case["vehicles"]
    c = case["contact"]
    n = np.asarray(c["normal"], dtype=float)
    n = n / np.linalg.norm(n)
    p = np.asarray(c["point"], dtype=float)
    r1 = p - np.asarray(v1["position"])
    r2 = p - np.asarray(v2["position"])
    u = (np.asarray(v1["velocity"]) + np.cross(v1["angular_velocity"], r1)) - (
        np.asarray(v2["velocity"]) + np.cross(v2["angular_velocity"], r2)
    )
    inv1 = np.linalg.inv(world_inertia(v1))
    inv2 = np.linalg.inv(world_inertia(v2))
    K = (1.0 / v1["mass"] + 1.0 / v2["mass"]) * np.eye(3) - skew(r1) @ inv1 @ skew(r1) - skew(r2) @ inv2 @ skew(r2)
    j_c = -np.linalg.solve(K, u)
    n_c = float(n @ j_c)
    t_c = j_c - n_c * n
    return dict(u=u, n=n, p=p, r1=r1, r2=r2, inv1=inv1, inv2=inv2, K=K, j_c=j_c, n_c=n_c, t_c=t_c)


def ks_impulse(case):
    """J on vehicle 1, sliding flag, branch name (docs/model.md, "The impulse exchange", steps 3-6)."""
    s = stick_split(case)
    eps, mu = float(case["contact"]["restitution"]), float(case["contact"]["friction"])
    u, n, K, n_c, t_c = s["u"], s["n"], s["K"], s["n_c"], s["t_c"]
    u_n = float(n @ u)
    if u_n >= 0:
        return np.zeros(3), False, "separating", s
    t_abs = float(np.linalg.norm(t_c))
    if n_c <= 0:
        t = t_c / t_abs
        d = n + mu * t
        N = -u_n / float(n @ K @ d)
        j_cs = N * d
        sliding, branch = True, "pull"
    else:
        s_star = 1.0 if t_abs == 0 else min(1.0, mu * n_c / t_abs)
        d = n + s_star * t_c / n_c
        N = -u_n / float(n @ K @ d)
        j_cs = N * d
        sliding = s_star < 1.0
        branch = "slide" if sliding else "stick"
    return (1.0 + eps) * j_cs, sliding, branch, s


def solve(case):
    """All section-4 results of one exchange at an explicit contact (time = 0)."""
    case = copy.deepcopy(case)
    status = input_status(case)
    nan3 = np.full(3, np.nan)
    if status != "ok":
        veh = dict(delta_v=nan3, delta_v_magnitude=np.nan, delta_v_body=nan3, delta_yaw_rate=np.nan,
                   velocity_after=nan3, speed_after=np.nan, course_after=np.nan, angular_velocity_after=nan3,
                   yaw_rate_after=np.nan, pdof=np.nan, pdof_clock=np.nan, crush=np.nan, ees=np.nan)
        con = dict(point=nan3, normal=nan3, time=np.nan, impulse=nan3, impulse_magnitude=np.nan,
                   impulse_normal=np.nan, impulse_tangential=np.nan, impulse_azimuth=np.nan,
                   impulse_elevation=np.nan, sliding=False, closing_velocity=nan3, separation_velocity=nan3,
                   energy_loss=np.nan, status=status)
        return {"contact": con, "vehicles": [veh, dict(veh)], "_": {}}

    j, sliding, branch, s = ks_impulse(case)
    if branch == "separating":
        status = "separating"
    v1, v2 = case["vehicles"]
    n, p, u = s["n"], s["p"], s["u"]

    after = []
    for veh, force, r, inv, into in ((v1, j, s["r1"], s["inv1"], -n), (v2, -j, s["r2"], s["inv2"], n)):
        m = veh["mass"]
        rot = rotation(veh["yaw"], veh["pitch"], veh["roll"])
        dv = force / m
        dw = inv @ np.cross(r, force)
        v_after = np.asarray(veh["velocity"]) + dv
        w_after = np.asarray(veh["angular_velocity"]) + dw
        f_body = rot.T @ force
        pdof = direction_degrees(f_body[1], -f_body[0])
        hour = round(pdof / 30.0) % 12
        after.append(dict(
            delta_v=dv, delta_v_magnitude=np.linalg.norm(j) / m, delta_v_body=rot.T @ dv, delta_yaw_rate=dw[2],
            velocity_after=v_after, speed_after=np.linalg.norm(v_after),
            course_after=direction_degrees(v_after[1], v_after[0]),
            angular_velocity_after=w_after, yaw_rate_after=w_after[2],
            pdof=pdof, pdof_clock=12.0 if hour == 0 else float(hour),
            crush=crush(veh, p, into),
        ))

    a1, a2 = after
    ke_before = kinetic_energy(v1, v1["velocity"], v1["angular_velocity"]) + kinetic_energy(
        v2, v2["velocity"], v2["angular_velocity"])
    ke_after = kinetic_energy(v1, a1["velocity_after"], a1["angular_velocity_after"]) + kinetic_energy(
        v2, a2["velocity_after"], a2["angular_velocity_after"])
    energy = ke_before - ke_after

    c_total = a1["crush"] + a2["crush"]
    for a, veh in ((a1, v1), (a2, v2)):
        if c_total > 0 and energy >= 0:
            a["ees"] = math.sqrt(2.0 * energy * a["crush"] / c_total / veh["mass"])
        else:  # Burg's split is undefined
            a["ees"] = np.nan

    u_after = (a1["velocity_after"] + np.cross(a1["angular_velocity_after"], s["r1"])) - (
        a2["velocity_after"] + np.cross(a2["angular_velocity_after"], s["r2"]))
    j_abs = float(np.linalg.norm(j))
    j_n = float(n @ j)
    con = dict(
        point=p, normal=n, time=0.0, impulse=j, impulse_magnitude=j_abs, impulse_normal=j_n,
        impulse_tangential=float(np.linalg.norm(j - j_n * n)),
        impulse_azimuth=direction_degrees(j[1], j[0]),
        impulse_elevation=math.degrees(math.asin(j[2] / j_abs)) if j_abs > 0 else 0.0,
        sliding=bool(sliding), closing_velocity=u, separation_velocity=u_after, energy_loss=energy,
        status=status,
    )
    internals = dict(s, branch=branch, ke_before=ke_before)
    return {"contact": con, "vehicles": [a1, a2], "_": internals}


# --------------------------------------------------------------------------- Brach's planar model
def brach_planar(case):
    """Brach's planar impact model (R. M. Brach, Mechanical Impact Dynamics), written in the
    contact frame (t, n) of the horizontal plane, for planar rigid bodies with yaw inertia
    I_i = Izz_i and contact arms (rho_it, rho_in) = components of P - x_i along (t, n),
    t = k x n.

    With P = (P_t, P_n) the impulse on vehicle 1, the contact-point relative velocity changes by
        du_t = A P_t + B P_n,   du_n = B P_t + C P_n,
        A = sum_i 1/m_i + rho_in^2 / I_i,  B = -sum_i rho_it rho_in / I_i,  C = sum_i 1/m_i + rho_it^2 / I_i.
    Brach's model: impulse ratio P_t = mu P_n and restitution on the normal contact velocity
    u_n' = -e u_n, so P_n = -(1 + e) u_n / (C + mu B). The critical ratio mu_0 is the one that
    also ends the tangential contact velocity (u_t' = 0); the contact slides when |mu| < |mu_0|,
    and then mu takes the sign of mu_0. The model presumes a compressive normal impulse
    (P_n0 > 0, returned as ``pn0``); the KS model's N_c <= 0 branch lies outside it.

    Returns dict(impulse (3,), sliding, mu0, velocity_after [2], yaw_rate_after [2], energy_loss).
    """
    v1, v2 = case["vehicles"]
    c = case["contact"]
    e, mu = float(c["restitution"]), float(c["friction"])
    nx, ny = float(c["normal"][0]), float(c["normal"][1])
    ln = math.hypot(nx, ny)
    nx, ny = nx / ln, ny / ln
    tx, ty = -ny, nx
    px, py = float(c["point"][0]), float(c["point"][1])

    def frame(vx, vy):
        return vx * tx + vy * ty, vx * nx + vy * ny

    A = B = 0.0
    C = 0.0
    u_t = u_n = 0.0
    for sign, v in ((1.0, v1), (-1.0, v2)):
        m = float(v["mass"])
        izz = float(body_inertia(v["inertia"])[2, 2])
        rx, ry = px - float(v["position"][0]), py - float(v["position"][1])
        rt, rn = frame(rx, ry)
        A += 1.0 / m + rn * rn / izz
        B += -rt * rn / izz
        C += 1.0 / m + rt * rt / izz
        wz = float(v["angular_velocity"][2])
        vpx = float(v["velocity"][0]) - wz * ry  # v + w k x r
        vpy = float(v["velocity"][1]) + wz * rx
        vt, vn = frame(vpx, vpy)
        u_t += sign * vt
        u_n += sign * vn

    # critical ratio: u_t' = 0 and u_n' = -e u_n  (2x2 solve by Cramer's rule)
    rhs_t, rhs_n = -u_t, -(1.0 + e) * u_n
    det = A * C - B * B
    pt0 = (rhs_t * C - B * rhs_n) / det
    pn0 = (A * rhs_n - B * rhs_t) / det
    mu0 = pt0 / pn0
    sliding = abs(mu) < abs(mu0)
    if sliding:
        ratio = math.copysign(mu, mu0)
        p_n = -(1.0 + e) * u_n / (C + ratio * B)
        p_t = ratio * p_n
    else:
        p_n, p_t = pn0, pt0
    jx, jy = p_t * tx + p_n * nx, p_t * ty + p_n * ny

    vel, yaw_rate = [], []
    ke0 = ke1 = 0.0
    for sign, v in ((1.0, v1), (-1.0, v2)):
        m = float(v["mass"])
        izz = float(body_inertia(v["inertia"])[2, 2])
        rx, ry = px - float(v["position"][0]), py - float(v["position"][1])
        vx, vy, wz = float(v["velocity"][0]), float(v["velocity"][1]), float(v["angular_velocity"][2])
        vx1, vy1 = vx + sign * jx / m, vy + sign * jy / m
        wz1 = wz + sign * (rx * jy - ry * jx) / izz
        vel.append(np.array([vx1, vy1]))
        yaw_rate.append(wz1)
        ke0 += 0.5 * m * (vx * vx + vy * vy) + 0.5 * izz * wz * wz
        ke1 += 0.5 * m * (vx1 * vx1 + vy1 * vy1) + 0.5 * izz * wz1 * wz1
    return dict(impulse=np.array([jx, jy, 0.0]), sliding=sliding, mu0=mu0, pn0=pn0, velocity_after=vel,
                yaw_rate_after=yaw_rate, energy_loss=ke0 - ke1, kinetic_energy=ke0)


# --------------------------------------------------------------------------- random cases
def random_spd(rng, principal):
    """A full symmetric positive-definite body inertia tensor around ``principal`` (3,):
    Q diag(principal) Q^T with a random rotation Q, plus a small random SPD perturbation."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    a = rng.normal(size=(3, 3)) * 0.1 * principal.min() ** 0.5
    m = q @ np.diag(principal) @ q.T + a @ a.T
    return 0.5 * (m + m.T)


def random_vehicle(rng, full_inertia=False, tilt=0.25):
    length = rng.uniform(3.5, 5.5)
    principal = np.array([rng.uniform(300, 900), rng.uniform(1500, 3500), rng.uniform(1700, 4000)])
    return dict(
        mass=rng.uniform(600, 3000),
        inertia=random_spd(rng, principal) if full_inertia else principal,
        length=length,
        width=rng.uniform(1.6, 2.1),
        height=rng.uniform(1.3, 1.9),
        cg_to_front=rng.uniform(0.4, 0.6) * length,
        cg_height=rng.uniform(0.4, 0.7),
        yaw=rng.uniform(-math.pi, math.pi),
        pitch=rng.uniform(-tilt, tilt),
        roll=rng.uniform(-tilt, tilt),
    )


def _body_point_in_box(rng, veh, inside=True):
    lo, hi = box_bounds(veh)
    if inside:
        return lo + (hi - lo) * rng.uniform(0.02, 0.98, size=3)
    q = lo + (hi - lo) * rng.uniform(0.02, 0.98, size=3)
    axis = rng.integers(3)
    q[axis] = hi[axis] + rng.uniform(0.05, 0.5) if rng.uniform() < 0.5 else lo[axis] - rng.uniform(0.05, 0.5)
    return q


def random_case(rng, full_inertia=False, tilt=0.25, normal_pitch=0.3, outside_fraction=0.15,
                approaching=True):
    """One random off-centre 3D case: random masses, inertias (principal or full SPD tensors),
    yaw/pitch/roll, angular velocities, a pitched normal, P inside both boxes (or, with
    probability ``outside_fraction``, outside vehicle 2's box) and off CG height.
    With ``approaching`` the closing velocity along n is made negative (u_n in [-15, -0.5] m/s)."""
    v1 = random_vehicle(rng, full_inertia, tilt)
    v2 = random_vehicle(rng, full_inertia, tilt)
    v1["position"] = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), v1["cg_height"] + rng.uniform(-0.1, 0.1)])
    r1 = rotation(v1["yaw"], v1["pitch"], v1["roll"])
    p = v1["position"] + r1 @ _body_point_in_box(rng, v1)
    r2 = rotation(v2["yaw"], v2["pitch"], v2["roll"])
    q2 = _body_point_in_box(rng, v2, inside=rng.uniform() >= outside_fraction)
    v2["position"] = p - r2 @ q2
    for v in (v1, v2):
        v["velocity"] = np.array([rng.normal(0, 10), rng.normal(0, 10), rng.normal(0, 0.5)])
        v["angular_velocity"] = np.array([rng.normal(0, 0.3), rng.normal(0, 0.3), rng.normal(0, 1.0)])
    az = rng.uniform(-math.pi, math.pi)
    el = rng.uniform(-normal_pitch, normal_pitch)
    n = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    case = {"vehicles": [v1, v2], "contact": dict(point=p, normal=n, restitution=rng.uniform(-0.3, 1.0),
                                                  friction=rng.uniform(0.0, 1.2))}
    if approaching:
        u = stick_split(case)["u"]
        target = -rng.uniform(0.5, 15.0)
        v2["velocity"] = v2["velocity"] + (float(n @ u) - target) * n
    return case


def planar_case(rng, friction=None, restitution=None):
    """A planar case for Brach's model: no pitch or roll, principal inertias, horizontal velocities
    and normal, yaw rates only, both CGs and P at the same height."""
    case = random_case(rng, full_inertia=False, tilt=0.0, normal_pitch=0.0, outside_fraction=0.0,
                       approaching=False)
    h = case["vehicles"][0]["cg_height"]
    for v in case["vehicles"]:
        v["cg_height"] = h
        v["position"][2] = h
        v["velocity"][2] = 0.0
        v["angular_velocity"][:2] = 0.0
    case["contact"]["point"][2] = h
    n = case["contact"]["normal"]
    if friction is not None:
        case["contact"]["friction"] = friction
    if restitution is not None:
        case["contact"]["restitution"] = restitution
    u = stick_split(case)["u"]
    v2 = case["vehicles"][1]
    v2["velocity"] = v2["velocity"] + (float(n @ u) + rng.uniform(0.5, 15.0)) * n
    return case


def swap(case):
    """The same scene with the vehicles exchanged and n flipped."""
    out = copy.deepcopy(case)
    out["vehicles"] = out["vehicles"][::-1]
    out["contact"]["normal"] = -np.asarray(out["contact"]["normal"])
    return out


def transform(case, rot=None, shift=None):
    """The whole scene rotated by the proper rotation ``rot`` (3, 3) about the origin, then
    translated by ``shift`` (3,). Orientations become rot @ R (re-expressed as yaw, pitch, roll)."""
    out = copy.deepcopy(case)
    rot = np.eye(3) if rot is None else np.asarray(rot)
    shift = np.zeros(3) if shift is None else np.asarray(shift)
    for v in out["vehicles"]:
        v["position"] = rot @ v["position"] + shift
        v["velocity"] = rot @ v["velocity"]
        v["angular_velocity"] = rot @ v["angular_velocity"]
        v["yaw"], v["pitch"], v["roll"] = euler_from_rotation(rot @ rotation(v["yaw"], v["pitch"], v["roll"]))
    out["contact"]["point"] = rot @ out["contact"]["point"] + shift
    out["contact"]["normal"] = rot @ out["contact"]["normal"]
    return out
