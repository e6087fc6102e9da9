"""Automatic contact (docs/model.md, "Automatic contact"): first-contact time, overlap centroid, normal, crush.

Every case is worked by hand (or by a second formulation: ``ks_jax.exchange`` at the hand-made
contact). One compiled program serves every test here: ``automatic_exchange`` and its JVP,
vmapped over a batch padded to BATCH rows, with the user-override flags as per-row arrays, compiled as
``ks_jax.solve`` and the fit compile a case's automatic contact and its forward-mode derivatives
(``ks_jax.compilation.quick_jit``). Single calls are checked against it without jit (``jax.disable_jit``).
"""

import io
import json
import math
from contextlib import redirect_stdout
from importlib import resources

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax.model import contact as G
from ks_jax.model.contact import search
from ks_jax import units as U
from ks_jax.case import as_arrays, load_case, set_input, to_pytrees
from ks_jax.compilation import quick_jit
from ks_jax.model.types import NO_CONTACT, OK
from samples import reference_jit

BATCH = 96
TIME_TOL = 1e-9  # s: closed form and bisection are both far below the 1e-6 s asked for
LEN_TOL = 1e-9  # m


def _auto(args, flags):
    return G.automatic_exchange(*args, auto_point=flags[0], auto_normal=flags[1])


def _auto_jvp(args, tangents):
    """The JVP of the automatic exchange's main results (``outputs``): only those are compiled."""
    return jax.jvp(lambda *a: outputs(_auto(a, (True, True))), args, tangents)


def _contact_jvp(args, tangents):
    """Only the automatic-contact part (time, point, normal): a smaller program to differentiate."""

    def f(v1, s1, v2, s2, c, pitch):
        a = G.automatic_contact(v1, s1, v2, s2, c, pitch, auto_point=True, auto_normal=True)
        normal = jnp.where(a.found, a.contact.normal, 0.0)  # never touching: a stand-in normal
        return jnp.concatenate([a.time[None], a.contact.point, normal])

    return jax.jvp(f, args, tangents)


AUTO = quick_jit(jax.vmap(_auto))
AUTO_JVP = quick_jit(jax.vmap(_auto_jvp))
CONTACT_JVP = quick_jit(jax.vmap(_contact_jvp))
EXCHANGE = reference_jit(ks_jax.exchange)  # the second formulation's exchange


def veh(length=4.5, width=1.8, height=1.4, cg_to_front=None, mass=1500.0, inertia=(500.0, 2500.0, 2700.0),
        cg_height=0.55):
    return ks_jax.Vehicle.create(mass, jnp.asarray(inertia, float), length, width, height, cg_to_front, cg_height)


def st(x, y, yaw_deg=0.0, speed=0.0, yaw_rate=0.0, cg_height=0.55):
    yaw = math.radians(yaw_deg)
    return ks_jax.State.create([x, y], yaw, speed=speed, yaw_rate=yaw_rate, cg_height=cg_height)


def con(penetration_time, restitution=0.1, friction=0.5, point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0)):
    return ks_jax.Contact.create(jnp.asarray(point, float), jnp.asarray(normal, float), restitution, friction,
                                 penetration_time=penetration_time)


def _zeros(tree):
    return jax.tree_util.tree_map(lambda x: jnp.zeros_like(jnp.asarray(x, float)), tree)


def stack(items):
    """The rows padded to BATCH, stacked in NumPy (no program compiled for the stacking)."""
    items = list(items) + [items[0]] * (BATCH - len(items))
    return jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *items)


def row_of(tree, i):
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[i], tree)


def _args(rows):
    return [tuple(r[:5]) + (jnp.asarray(r[5], float),) for r in rows]


def run(rows, flags=None):
    """AUTO over rows (padded to BATCH), NumPy results per row. rows: (vehicle1, state1,
    vehicle2, state2, contact, pitch); flags: (auto_point, auto_normal) per row."""
    rows = _args(rows)
    flags = flags or [(True, True)] * len(rows)
    out = AUTO(stack(rows), stack([jnp.array(f) for f in flags]))
    return [row_of(out, i) for i in range(len(rows))]


def run_jvp(fn, rows, tangents):
    rows = _args(rows)
    out, tan = fn(stack(rows), stack(tangents))
    return [row_of(out, i) for i in range(len(rows))], [row_of(tan, i) for i in range(len(rows))]


# ---------------------------------------------------------------------------------------
# the hand cases

V1 = veh(length=4.6, width=1.8, height=1.4, cg_to_front=2.1)
V2 = veh(length=4.8, width=1.9, height=1.5, cg_to_front=2.6, mass=1800.0)
V2T = veh(length=4.8, width=1.9, height=1.5, cg_to_front=2.4, mass=1800.0)
VS = veh(length=4.5, width=1.8, height=1.4, cg_to_front=2.25)

# oblique: vehicle 2 at 60 deg, 10 m/s; its front-left corner reaches (0.3, -0.9) at t = 0.3 s
OBL_YAW = math.radians(60.0)
OBL_CORNER = np.array([2.4 * math.cos(OBL_YAW) - 0.95 * math.sin(OBL_YAW),
                       2.4 * math.sin(OBL_YAW) + 0.95 * math.cos(OBL_YAW)])
OBL_V = 10.0 * np.array([math.cos(OBL_YAW), math.sin(OBL_YAW)])
OBL_X2 = np.array([0.3, -0.9]) - OBL_CORNER - 0.3 * OBL_V

# spinning: vehicle 1 turns at 2 rad/s about its CG at the origin; vehicle 2 parked sideways, face at x = 2.35
SPIN_W, SPIN_X = 2.0, 2.35
SPIN_R, SPIN_PHI = math.hypot(2.25, 0.9), math.atan2(0.9, 2.25)
SPIN_T = (SPIN_PHI - math.acos(SPIN_X / SPIN_R)) / SPIN_W  # front-right corner reaches x = SPIN_X


def seed_row(name, x1_ft, x2_ft, penetration_time):
    with resources.as_file(resources.files("ks_jax.cases") / name) as path:
        case = load_case(path)
    inp = as_arrays(case.inputs)
    inp = set_input(inp, "vehicles[0].position[0]", x1_ft * U.FT)
    inp = set_input(inp, "vehicles[1].position[0]", x2_ft * U.FT)
    inp = set_input(inp, "contact.penetration_time", penetration_time)
    v1, s1, v2, s2, c = to_pytrees(inp)
    v1 = v1._replace(inertia=jnp.diag(v1.inertia))  # principal moments: one batch shape
    v2 = v2._replace(inertia=jnp.diag(v2.inertia))
    return (v1, s1, v2, s2, c, 0.0), inp


SEED0, SEED0_IN = seed_row("seed_000_saturn_pontiac.json", 10.0, -10.0, 0.06)
SEED1, SEED1_IN = seed_row("seed_001_lucid_kia.toml", 0.0, -20.0, 0.06)

CASES = {
    "rear": (V1, st(10.0, 0.0, 0, 5.0), V2, st(0.0, 0.0, 0, 15.0), con(0.03), 0.0),
    "tbone": (V1, st(0.0, 0.0), V2T, st(0.5, -6.0, 90, 10.0), con(0.02), 0.0),
    "oblique": (V1, st(0.0, 0.0), V2T, st(OBL_X2[0], OBL_X2[1], 60, 10.0), con(0.01), 0.0),
    "spin": (VS, st(0.0, 0.0, yaw_rate=SPIN_W), VS, st(SPIN_X + 0.9, 0.0, 90), con(0.0), 0.0),
    "never": (VS, st(0.0, 0.0, 0, 5.0), VS, st(0.0, 5.0, 0, 5.0), con(0.02), 0.0),
    "overlap": (VS, st(0.0, 0.0), VS, st(-4.0, 0.0, 0, 3.0), con(0.02), 0.0),
    "seed0": SEED0,
    "seed1": SEED1,
    "pitched": (V1, st(10.0, 0.0, 0, 5.0), V2, st(0.0, 0.0, 0, 15.0), con(0.03), math.radians(10.0)),
    "deep_rear": (V1, st(10.0, 0.0, 0, 5.0), V2, st(0.0, 0.0, 0, 15.0), con(0.3), 0.0),
}


USER_N = jnp.array([math.cos(math.radians(80)), math.sin(math.radians(80)), 0.0])
USER_P = jnp.array([0.2, -0.85, 0.6])
OVERRIDES = {  # oblique case with a user normal (automatic point) / a user point (automatic normal)
    "point_only": ((*CASES["oblique"][:4], CASES["oblique"][4]._replace(normal=USER_N), 0.0), (True, False)),
    "normal_only": ((*CASES["oblique"][:4], CASES["oblique"][4]._replace(point=USER_P), 0.0), (False, True)),
}


@pytest.fixture(scope="module")
def res():
    names = list(CASES) + list(OVERRIDES)
    rows = [CASES[n] for n in CASES] + [OVERRIDES[n][0] for n in OVERRIDES]
    flags = [(True, True)] * len(CASES) + [OVERRIDES[n][1] for n in OVERRIDES]
    return dict(zip(names, run(rows, flags=flags)))


def second_formulation(case, t_exchange, point, normal):
    """ks_jax.exchange with the vehicles moved by hand and the contact written by hand."""
    v1, s1, v2, s2, c, _ = case
    adv = lambda s: s._replace(position=s.position + s.velocity * t_exchange,  # noqa: E731
                               yaw=s.yaw + s.angular_velocity[2] * t_exchange)
    c = c._replace(point=jnp.asarray(point, float), normal=jnp.asarray(normal, float))
    return jax.tree_util.tree_map(np.asarray, EXCHANGE(v1, adv(s1), v2, adv(s2), c))


def assert_same_exchange(r, ref, rtol=1e-9):
    for name in ("impulse", "energy_loss", "closing_velocity", "separation_velocity"):
        a, b = getattr(r.contact, name), getattr(ref.contact, name)
        np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * (1 + np.max(np.abs(b))), err_msg=name)
    for i in range(2):
        for name in ("delta_v", "velocity_after", "angular_velocity_after", "crush", "ees", "pdof"):
            a, b = getattr(r.vehicles[i], name), getattr(ref.vehicles[i], name)
            np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * (1 + np.max(np.abs(b))),
                                       err_msg=f"vehicles[{i}].{name}")


@pytest.mark.slow
def test_aligned_rear_impact(res):
    r = res["rear"]
    # gap: rear of 1 at 10 + 2.1 - 4.6 = 7.5, front of 2 at 2.6; closing 10 m/s
    assert r.contact.status == OK
    assert abs(r.contact.time - 0.49) < TIME_TOL
    # at 0.52 s: rear of 1 at 10.1, front of 2 at 10.4; vertical overlap [0, 1.4] -> z = 0.7
    np.testing.assert_allclose(r.contact.point, [10.25, 0.0, 0.7], atol=LEN_TOL)
    np.testing.assert_allclose(r.contact.normal, [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose([v.crush for v in r.vehicles], [0.15, 0.15], atol=LEN_TOL)
    assert [float(v.pdof_clock) for v in r.vehicles] == [6.0, 12.0]
    assert_same_exchange(r, second_formulation(CASES["rear"], 0.52, [10.25, 0.0, 0.7], [1.0, 0.0, 0.0]))


@pytest.mark.slow
def test_penetration_deeper_than_the_overlap_is_wide(res):
    """The rear impact above with 0.3 s of penetration: 3 m deep, 1.8 m wide, so the axis of least
    penetration is lateral; the normal must still point from vehicle 2 into vehicle 1 (+x)."""
    r = res["deep_rear"]
    assert r.contact.status == OK
    # at 0.79 s: rear of 1 at 10 + 3.95 - 2.5 = 11.45, front of 2 at 2.6 + 11.85 = 14.45
    np.testing.assert_allclose(r.contact.point, [12.95, 0.0, 0.7], atol=LEN_TOL)
    np.testing.assert_allclose(r.contact.normal, [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose([v.crush for v in r.vehicles], [1.5, 1.5], atol=LEN_TOL)
    assert [float(v.pdof_clock) for v in r.vehicles] == [6.0, 12.0]
    assert_same_exchange(r, second_formulation(CASES["deep_rear"], 0.79, [12.95, 0.0, 0.7], [1.0, 0.0, 0.0]))


@pytest.mark.slow
def test_normal_pitch_tilts_the_automatic_normal(res):
    r, p = res["pitched"], math.radians(10.0)
    np.testing.assert_allclose(r.contact.normal, [math.cos(p), 0.0, math.sin(p)], atol=1e-12)
    np.testing.assert_allclose(r.contact.point, res["rear"].contact.point, atol=LEN_TOL)


@pytest.mark.slow
def test_tbone_into_the_right_side(res):
    r = res["tbone"]
    # front of 2 at -6 + 2.4 = -3.6, right side of 1 at -0.9, closing 10 m/s
    assert abs(r.contact.time - 0.27) < TIME_TOL
    # at 0.29 s the front of 2 is at y = -0.7: overlap x in [0.5 -+ 0.95], y in [-0.9, -0.7]
    np.testing.assert_allclose(r.contact.point, [0.5, -0.8, 0.7], atol=LEN_TOL)
    np.testing.assert_allclose(r.contact.normal, [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose([v.crush for v in r.vehicles], [0.1, 0.1], atol=LEN_TOL)
    assert float(r.vehicles[0].pdof_clock) == 3.0  # struck from its right
    assert float(r.vehicles[1].pdof_clock) == 12.0  # frontal
    assert_same_exchange(r, second_formulation(CASES["tbone"], 0.29, [0.5, -0.8, 0.7], [0.0, 1.0, 0.0]))


@pytest.mark.slow
def test_oblique_corner_impact(res):
    r = res["oblique"]
    assert abs(r.contact.time - 0.3) < TIME_TOL
    # the corner has gone delta = 10 sin60 * 0.01 past y = -0.9: a triangle cut by that line
    delta = 10.0 * math.sin(OBL_YAW) * 0.01
    apex = np.array([0.3, -0.9]) + OBL_V * 0.01
    side = -np.array([math.cos(OBL_YAW), math.sin(OBL_YAW)])  # along the left side, rearwards
    front = np.array([math.sin(OBL_YAW), -math.cos(OBL_YAW)])  # along the front face, to the right
    p1 = apex + delta / math.sin(OBL_YAW) * side
    p2 = apex + delta / math.cos(OBL_YAW) * front
    centroid = (apex + p1 + p2) / 3.0
    np.testing.assert_allclose(r.contact.point[:2], centroid, atol=LEN_TOL)
    np.testing.assert_allclose(r.contact.normal, [0.0, 1.0, 0.0], atol=1e-12)  # through p1, p2
    assert abs(r.vehicles[0].crush - delta / 3.0) < LEN_TOL
    assert_same_exchange(r, second_formulation(CASES["oblique"], 0.31, [*centroid, 0.7], [0.0, 1.0, 0.0]))


def test_spinning_car_reaches_a_parked_one(res):
    r = res["spin"]
    assert abs(r.contact.time - SPIN_T) < TIME_TOL
    # penetration_time 0: the exchange is at the touching corner, n along -x (from 2 into 1)
    angle = -SPIN_PHI + SPIN_W * SPIN_T
    corner = SPIN_R * np.array([math.cos(angle), math.sin(angle)])
    np.testing.assert_allclose(r.contact.point, [corner[0], corner[1], 0.7], atol=1e-8)
    np.testing.assert_allclose(r.contact.normal, [-1.0, 0.0, 0.0], atol=1e-12)
    assert r.contact.status == OK and r.contact.impulse[0] < 0  # pushed back, away from the parked car
    assert_same_exchange(r, second_formulation(CASES["spin"], SPIN_T, [corner[0], corner[1], 0.7],
                                               [-1.0, 0.0, 0.0]), rtol=1e-7)


def test_never_touching(res):
    r = res["never"]
    assert r.contact.status == NO_CONTACT and ks_jax.status_text(r.contact.status) == "no_contact"
    assert r.contact.time == G.HORIZON
    assert all(np.all(np.isfinite(x)) for x in jax.tree_util.tree_leaves(r))
    np.testing.assert_array_equal(r.contact.impulse, 0.0)
    for v, s in zip(r.vehicles, (CASES["never"][1], CASES["never"][3])):
        np.testing.assert_array_equal(v.delta_v, 0.0)
        np.testing.assert_allclose(v.velocity_after, s.velocity)
        assert v.crush == 0 and v.ees == 0


def test_already_overlapping(res):
    r = res["overlap"]
    assert r.contact.time == 0.0
    # rear of 1 at -2.25; front of 2 at -4 + 2.25 + 3 * 0.02 = -1.69
    np.testing.assert_allclose(r.contact.point, [-1.97, 0.0, 0.7], atol=LEN_TOL)
    np.testing.assert_allclose([v.crush for v in r.vehicles], [0.28, 0.28], atol=LEN_TOL)


def test_seed_chapter_stagings(res):
    # 000: Saturn rear at 10 + 6.86067 - 15.87 ft, Pontiac front at -10 + 7.283 ft, closing 16 mph
    gap0 = (10 + 6.86067 - 15.87) - (-10 + 7.283)
    t0 = gap0 * U.FT / (16 * U.MPH)
    r0 = res["seed0"]
    assert abs(r0.contact.time - t0) < TIME_TOL and abs(r0.contact.time - 0.16) < 0.005  # manual's timing
    # the middle of the overlap: crush split equally, 1/2 of 16 mph * 0.06 s each
    np.testing.assert_allclose([v.crush for v in r0.vehicles], [0.5 * 16 * U.MPH * 0.06] * 2, rtol=1e-9)
    np.testing.assert_allclose(r0.contact.point[2], 2.3 * U.FT, rtol=1e-12)  # middle of two 4.6 ft boxes
    # 001: Lucid rear at 8.1 - 16.3 = -8.2 ft, Kia front at -20 + 6.85 = -13.15 ft, closing 15 mph
    r1 = res["seed1"]
    assert abs(r1.contact.time - 4.95 * U.FT / (15 * U.MPH)) < TIME_TOL
    assert abs(r1.contact.time - 0.225) < 1e-9
    for r, inp in ((r0, SEED0_IN), (r1, SEED1_IN)):
        np.testing.assert_allclose(r.contact.normal, [1.0, 0.0, 0.0], atol=1e-12)
        assert [float(v.pdof_clock) for v in r.vehicles] == [6.0, 12.0]


def test_user_contact_overrides_one_part(res):
    auto = res["oblique"].contact
    point_only, normal_only = res["point_only"], res["normal_only"]
    np.testing.assert_allclose(point_only.contact.point, auto.point, atol=1e-12)
    np.testing.assert_allclose(point_only.contact.normal, USER_N, atol=1e-12)
    np.testing.assert_allclose(normal_only.contact.point, USER_P, atol=1e-12)
    np.testing.assert_allclose(normal_only.contact.normal, auto.normal, atol=1e-12)
    for r in (point_only, normal_only):
        assert abs(r.contact.time - 0.3) < TIME_TOL
        assert_same_exchange(r, second_formulation(CASES["oblique"], 0.31, r.contact.point, r.contact.normal))
    # the overrides matter: the crush is measured along the user normal, the lever arms from the user point
    delta = 10.0 * math.sin(OBL_YAW) * 0.01
    assert abs(point_only.vehicles[0].crush - delta / 3.0 / math.sin(math.radians(80))) < LEN_TOL
    assert not np.allclose(normal_only.contact.impulse, auto.impulse, rtol=1e-3)


@pytest.mark.slow
def test_vmap_equals_single_calls(res):
    """The batched, jitted kernel row by row against plain single calls (no jit at all)."""
    with jax.disable_jit():
        for name in ("spin",):  # rotation: the scan, the bisection and the implicit step
            args = CASES[name][:5] + (jnp.asarray(CASES[name][5], float),)
            single = G.automatic_exchange(*args, auto_point=True, auto_normal=True)
            for a, b in zip(jax.tree_util.tree_leaves(single), jax.tree_util.tree_leaves(res[name])):
                np.testing.assert_allclose(np.asarray(a), b, rtol=1e-9, atol=1e-9, err_msg=name)


# ---------------------------------------------------------------------------------------
# gradients against central differences

THETA = ("speed1", "speed2", "yaw2", "x2", "y2", "penetration_time", "yaw_rate1")


def build(theta, base):
    """(vehicle1, state1, vehicle2, state2, contact, pitch) from theta (7,) (see THETA) and the
    constant rest of a case; heading = yaw = course of vehicle 2."""
    v1, s1, v2, s2, c = base
    vel1 = theta[0] * jnp.stack([jnp.cos(s1.yaw), jnp.sin(s1.yaw), 0.0 * theta[0]])
    vel2 = theta[1] * jnp.stack([jnp.cos(theta[2]), jnp.sin(theta[2]), 0.0 * theta[1]])
    s1 = s1._replace(velocity=vel1, angular_velocity=jnp.stack([0.0 * theta[6], 0.0 * theta[6], theta[6]]))
    s2 = s2._replace(velocity=vel2, yaw=theta[2], position=jnp.stack([theta[3], theta[4], s2.position[2]]))
    return v1, s1, v2, s2, c._replace(penetration_time=theta[5]), jnp.zeros_like(theta[0])


def outputs(r):
    c, (a, b) = r.contact, r.vehicles
    return jnp.stack([c.time, c.point[0], c.point[1], c.normal[0], c.normal[1], c.impulse[0], c.impulse[1],
                      a.delta_v_magnitude, b.delta_v_magnitude, a.crush, b.crush, c.energy_loss, a.yaw_rate_after])


GRAD_CASES = {  # theta and base; away from feature changes
    "oblique": ([3.0, 10.0, OBL_YAW, *OBL_X2, 0.01, 0.0], CASES["oblique"][:5]),
    "tbone": ([2.0, 10.0, math.radians(88.0), 0.5, -6.0, 0.02, 0.0], CASES["tbone"][:5]),
    "spin": ([0.0, 0.0, math.pi / 2, SPIN_X + 0.9, 0.1, 0.01, SPIN_W], CASES["spin"][:5]),
    "never": ([5.0, 5.0, 0.0, 0.0, 5.0, 0.02, 0.0], CASES["never"][:5]),
}


def _gradient_check(fn, value, names):
    """fn's forward-mode derivatives along each theta direction against central differences of
    ``value`` (a function of AUTO's per-row result), for the GRAD_CASES in ``names``."""
    n_theta, h = len(THETA), 1e-6
    rows, tangents, fd_rows = [], [], []
    for name in names:
        theta, base = np.array(GRAD_CASES[name][0], float), GRAD_CASES[name][1]
        for j in range(n_theta):
            e = jnp.asarray(np.eye(n_theta)[j])
            primal, tangent = jax.jvp(lambda th: build(th, base), (jnp.asarray(theta),), (e,))
            rows.append(primal)
            tangents.append(tangent)
        for j in range(n_theta):
            for sgn in (1.0, -1.0):
                fd_rows.append(build(jnp.asarray(theta + sgn * h * np.eye(n_theta)[j]), base))
    assert len(rows) <= BATCH and len(fd_rows) <= BATCH
    out, tan = run_jvp(fn, rows, [jax.tree_util.tree_map(lambda x: jnp.asarray(x, float), t) for t in tangents])
    fd_out = [value(r) for r in run(fd_rows)]
    for k, name in enumerate(names):
        for j in range(n_theta):
            f0 = np.asarray(out[k * n_theta + j] if not hasattr(out[0], "contact") else value(out[k * n_theta + j]))
            t = tan[k * n_theta + j]
            jac = np.asarray(t if not hasattr(t, "contact") else value(t))
            fd = (fd_out[2 * (k * n_theta + j)] - fd_out[2 * (k * n_theta + j) + 1]) / (2 * h)
            assert np.all(np.isfinite(jac)), name
            tol = 1e-6 * (1 + np.abs(f0)) + 1e-5 * np.abs(fd)
            bad = np.abs(jac - fd) > tol
            assert not np.any(bad), (f"{name}, d/d{THETA[j]}: outputs {np.flatnonzero(bad)}: "
                                     f"derivative {jac[bad]} vs differences {fd[bad]}")
            if name == "never":  # finite, and the time stays at the horizon
                assert jac[0] == 0
            if name == "oblique":  # by hand: the corner's y reaches -0.9 at t = 0.3 s
                want = {"speed1": 0.0, "speed2": -0.3 / 10.0, "y2": -1.0 / (10.0 * math.sin(OBL_YAW)),
                        "penetration_time": 0.0}.get(THETA[j])
                if want is not None:
                    assert abs(jac[0] - want) < 1e-9, THETA[j]


def _contact_value(r):
    normal = r.contact.normal if r.contact.status != NO_CONTACT else np.zeros(3)
    return np.concatenate([[r.contact.time], r.contact.point, normal])


@pytest.mark.slow
def test_contact_gradients_match_central_differences():
    """Time, centroid and normal: implicit differentiation of the touching condition and the
    overlap geometry, against central differences of the full kernel."""
    _gradient_check(CONTACT_JVP, _contact_value, list(GRAD_CASES))


@pytest.mark.slow
def test_result_gradients_match_central_differences():
    """End to end: impulse, delta-V, crush, energy, yaw rate after (compiles the JVP of the whole
    kernel, exchange included)."""
    _gradient_check(AUTO_JVP, lambda r: np.asarray(outputs(jax.tree_util.tree_map(jnp.asarray, r))),
                    ["oblique", "spin", "never"])


# ---------------------------------------------------------------------------------------
# shipped case files through the command line


def cli_json(path, png):
    from ks_jax.cli import main

    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["solve", str(path), "--json", "--plot", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    return json.loads(buf.getvalue())["cases"][0]


@pytest.mark.slow
def test_shipped_automatic_cases_through_the_cli(tmp_path):
    with resources.as_file(resources.files("ks_jax.cases") / "auto_seed_000.json") as path:
        d = cli_json(path, tmp_path / "seed0.png")
    gap = (10 + 6.86067 - 15.87) - (-10 + 7.283)
    assert d["contact"]["status"] == "ok"
    assert abs(d["contact"]["time"] - gap * U.FT / (16 * U.MPH)) < TIME_TOL
    assert d["vehicles"][0]["crush"] == pytest.approx(0.5 * 16 * U.MPH * 0.06, rel=1e-9)
    assert d["contact"]["normal"] == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)

    with resources.as_file(resources.files("ks_jax.cases") / "auto_tbone.json") as path:
        d = cli_json(path, tmp_path / "tbone.png")
    # pickup front at -30 + 8 ft, sedan's right side at -3 ft, pickup at 30 mph = 44 ft/s
    assert abs(d["contact"]["time"] - 19.0 / 44.0) < TIME_TOL
    assert d["contact"]["normal"] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    # centroid: x of the pickup (6 ft), y in the middle of 2.2 ft of penetration of the side
    x, y, _ = d["contact"]["point"]
    assert x == pytest.approx(6.0 * U.FT, abs=1e-9) and y == pytest.approx((-3.0 + 1.1) * U.FT, abs=1e-9)
    assert 270 < d["vehicles"][1]["pdof"] < 360  # pickup: frontal, dragged to its right by the sedan
    assert d["vehicles"][0]["pdof"] < 90  # from the right front quarter: the sedan drives into the force


@pytest.mark.slow
def test_never_touching_case_reads_as_such(tmp_path):
    """Through the command line: no first-contact time, PDOF, centroid, normal, relative velocities or EES
    where nothing was exchanged (the exchange's are stand-ins), in the panel and in the JSON (null), and the
    panel names the search horizon."""
    from ks_jax.cli import main

    raw = json.loads((resources.files("ks_jax.cases") / "auto_seed_000.json").read_text())
    raw["vehicles"][1]["position"] = ["-10 ft", "12 ft"]  # the next lane: never touching
    path = tmp_path / "apart.json"
    path.write_text(json.dumps(raw))
    for flags in ([], ["--json"]):
        buf = io.StringIO()
        with redirect_stdout(buf):
            assert main(["solve", str(path), *flags]) == 0
        out = buf.getvalue()
        if flags:
            d = json.loads(out)["cases"][0]
            assert d["contact"]["status"] == "no_contact" and d["contact"]["time"] is None
            assert all(v["pdof"] is None and v["pdof_clock"] is None and v["ees"] is None for v in d["vehicles"])
            assert all(d["contact"][k] is None for k in ("point", "normal", "closing_velocity", "separation_velocity"))
            assert d["contact"]["impulse_magnitude"] == 0.0 and d["contact"]["energy_loss"] == 0.0
            assert [v["crush"] for v in d["vehicles"]] == [0.0, 0.0]
        else:
            assert f"none within {G.HORIZON:g} s of free motion" in out and "o'clock" not in out
            assert out.count("undefined (no impulse)") == 2
            assert [line.split() for line in out.splitlines() if line.strip().startswith("EES")] == [
                ["EES", "undefined"]] * 2


def _turned(row, degrees):
    """The case ``row`` (vehicles at st(...) positions, both yaws) turned about the origin by ``degrees``."""
    v1, s1, v2, s2, c, pitch = row
    a = math.radians(degrees)
    rot = jnp.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    turn = lambda s: s._replace(position=rot @ s.position, velocity=rot @ s.velocity, yaw=s.yaw + a)  # noqa: E731
    return v1, turn(s1), v2, turn(s2), c, pitch


def test_inline_crashes_of_equal_widths_in_a_turned_scene():
    """Equal widths put the two boxes' sides on one line, where docs/model.md, "Automatic contact" takes the axis of
    least penetration. Turned by any angle the sides miss each other by ~1e-16 m of rounding, which
    must not count as two crossings (their line is the overlap's diagonal: a normal 36 deg off the
    axis and a yaw from a symmetric head-on): the results turn with the scene (section 3).
    By hand: rear-end, gap 7.75 - 2.25 = 5.5 m closing at 10 m/s, 0.3 m deep after 0.03 s: centroid
    x = 10.8, crush 0.15 each, n = +x; head-on, gap 5.5 m closing at 20 m/s, 0.6 m deep: x = 5.0,
    crush 0.3 each, n = -x (from 2 into 1)."""
    rear = (VS, st(10.0, 0.0, 0, 5.0), VS, st(0.0, 0.0, 0, 15.0), con(0.03), 0.0)
    head_on = (VS, st(0.0, 0.0, 0, 10.0), VS, st(10.0, 0.0, 180, 10.0), con(0.03), 0.0)
    angles = [0.0, 30.0, 45.0, 90.0, 135.0, 210.0, -90.0, 17.3]
    rows = [_turned(r, a) for r in (rear, head_on) for a in angles]
    out = run(rows)
    for k, (r, a) in enumerate(zip(out, angles * 2)):
        x, sign, crush = (10.8, 1.0, 0.15) if k < len(angles) else (5.0, -1.0, 0.3)
        c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
        where = f"{'rear' if k < len(angles) else 'head-on'} turned {a} deg"
        assert r.contact.status == OK, where
        np.testing.assert_allclose(r.contact.normal, [sign * c, sign * s, 0.0], atol=1e-12, err_msg=where)
        np.testing.assert_allclose(r.contact.point, [x * c, x * s, 0.7], atol=LEN_TOL, err_msg=where)
        np.testing.assert_allclose([v.crush for v in r.vehicles], [crush, crush], atol=LEN_TOL, err_msg=where)
        np.testing.assert_allclose([v.delta_yaw_rate for v in r.vehicles], [0.0, 0.0], atol=1e-9, err_msg=where)


def test_normal_sign_with_the_cgs_at_the_touching_faces():
    """Each CG 0.2 m from the face that touches (a CG may be anywhere along its box): 0.5 m into the
    rear-end, CG 2 (x = 15.15) is ahead of CG 1 (15.05), yet vehicle 2 is behind. The normal still
    points from vehicle 2 into vehicle 1 (+x) and the exchange is the hand one: gap 9.8 - 0.2 = 9.6 m
    at 10 m/s, t_i = 0.96 s; at 1.01 s the overlap is x in [14.85, 15.35], crush 0.25 each."""
    lead = veh(length=4.6, width=1.8, height=1.4, cg_to_front=4.4)
    follower = veh(length=4.8, width=1.9, height=1.5, cg_to_front=0.2, mass=1800.0)
    row = (lead, st(10.0, 0.0, 0, 5.0), follower, st(0.0, 0.0, 0, 15.0), con(0.05), 0.0)
    (r,) = run([row])
    assert r.contact.status == OK
    assert abs(r.contact.time - 0.96) < TIME_TOL
    np.testing.assert_allclose(r.contact.normal, [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(r.contact.point, [15.1, 0.0, 0.7], atol=LEN_TOL)
    np.testing.assert_allclose([v.crush for v in r.vehicles], [0.25, 0.25], atol=LEN_TOL)
    assert_same_exchange(r, second_formulation(row, 1.01, [15.1, 0.0, 0.7], [1.0, 0.0, 0.0]))


# ---------------------------------------------------------------------------------------
# where a vehicle rotates: the scan covers only the window in which the footprints can reach


def _graze_row(dur, yaw_rate):
    """VS parked at the origin (turning at ``yaw_rate``) and VS passing at (-20, -10) m/s: its rear-left
    corner crosses vehicle 1's front-right one. x-ranges start to overlap at t0 = 0.3911 s, y-ranges
    stop at t0 + dur: a graze of ``dur`` s. At t0 + dur/4 the overlap is the rectangle
    x in [2.25 - 20 dur/4, 2.25], y in [-0.9, -0.9 + 10 * 3 dur/4]."""
    t0, vx, vy = 0.3911, 20.0, 10.0
    s2 = ks_jax.State.create([4.5 + vx * t0, vy * (t0 + dur) - 1.8], 0.0, velocity=[-vx, -vy], cg_height=0.55)
    s1 = st(0.0, 0.0, yaw_rate=yaw_rate)
    return (VS, s1, VS, s2, con(dur / 4), 0.0), t0


def test_short_graze_of_a_rotating_vehicle_is_found():
    """Grazes of 1 ms and 0.2 ms, shorter than the 5 ms a scan of the whole 10 s horizon would step:
    the search keeps to the window in which the circles of reach about the CGs overlap (here 0.29 s),
    so its least step is 0.29 s / 2000 = 0.14 ms. Vehicle 1 turns at 1e-9 rad/s (the scan; a
    corner moves ~1e-9 m), so the hand geometry of the translating pair holds."""
    out = run([_graze_row(dur, w)[0] for dur in (1e-3, 2e-4) for w in (1e-9, 0.0)])
    for r, (dur, w) in zip(out, [(d, w) for d in (1e-3, 2e-4) for w in (1e-9, 0.0)]):
        where = f"graze of {dur} s, yaw rate {w}"
        assert r.contact.status == OK, where
        assert abs(r.contact.time - 0.3911) < TIME_TOL, where
        dx, dy = 20.0 * dur / 4, 10.0 * 3 * dur / 4
        np.testing.assert_allclose(r.contact.point, [2.25 - dx / 2, -0.9 + dy / 2, 0.7], atol=1e-8, err_msg=where)
        # the outlines cross at the overlap's other two corners, on vehicle 1's front and right side and
        # vehicle 2's rear and left side: faces that face each other, so the normal is the axis of least
        # penetration, x (dx = 0.75 dy), from vehicle 2 (ahead, to the right) into vehicle 1: -x. Turned
        # by the 4e-10 rad vehicle 1 has turned where it yaws
        np.testing.assert_allclose(r.contact.normal, [-1.0, 0.0, 0.0], atol=1e-9 if w else 1e-12, err_msg=where)


def _first_touch_of_a_spinning_car(w, u, face0):
    """Independent of the kernel: VS (corners at radius R, angles +-phi and pi +- phi) spins at w about
    the origin; a wall x = face0 - u t comes towards it. The first t at which a corner reaches the wall:
    a scan every 1e-5 s, then bisection."""
    R, phi = math.hypot(2.25, 0.9), math.atan2(0.9, 2.25)
    g = lambda t: R * max(math.cos(a + w * t) for a in (phi, -phi, math.pi + phi, math.pi - phi)) + u * t - face0  # noqa: E731
    t = 0.0
    while g(t + 1e-5) < 0:
        t += 1e-5
    lo, hi = t, t + 1e-5
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if g(mid) >= 0 else (mid, hi)
    return hi


def test_spinning_car_reached_late_and_out_of_reach():
    """A spinning car at the origin, reached by the 1.9 m wide face of a 10 m long vehicle turned across
    its path: from 24.05 m at 3 m/s it comes within reach after ~7.2 s; the touching time against an
    independent corner-against-wall calculation. Starting from 44.05 m it would arrive after 10 s
    (the horizon): no contact. A spinning car passing 5 m beside another, parallel and at the same
    speed, never comes within reach: no contact, and nothing NaN."""
    wall = veh(length=10.0, width=1.9, height=1.5, cg_to_front=5.0, mass=1800.0)
    w, u = 2.0, 3.0
    rows = [(VS, st(0.0, 0.0, yaw_rate=w), wall,
             ks_jax.State.create([face + 0.95, 0.0], math.pi / 2, velocity=[-u, 0.0], cg_height=0.55), con(0.0), 0.0)
            for face in (24.05, 44.05)]
    rows.append((VS, st(0.0, 0.0, 0, 5.0, yaw_rate=1.0), VS, st(0.0, 5.0, 0, 5.0), con(0.02), 0.0))
    late, too_late, beside = run(rows)
    want = _first_touch_of_a_spinning_car(w, u, 24.05)
    assert 7.0 < want < 10.0
    assert late.contact.status == OK and abs(late.contact.time - want) < 1e-9
    for r in (too_late, beside):
        assert r.contact.status == NO_CONTACT and r.contact.time == G.HORIZON
        assert all(np.all(np.isfinite(x)) for x in jax.tree_util.tree_leaves(r))


def _numpy_touching(dims, poses, t):
    """Independent of the kernel: (len(t),) bool, whether two boxes touch at the times t. dims: per vehicle
    (length, width, cg_to_front); poses: per vehicle (x, y, yaw, vx, vy, yaw_rate). Separating axes: the
    four edge normals, projections of the corners compared."""
    boxes = []
    for (length, width, front), (x, y, yaw, vx, vy, w) in zip(dims, poses):
        a = yaw + w * t
        bx = np.array([front - length, front, front, front - length])
        by = np.array([-1.0, -1.0, 1.0, 1.0]) * width / 2
        c, s = np.cos(a)[:, None], np.sin(a)[:, None]
        boxes.append((np.stack([x + vx * t[:, None] + c * bx - s * by, y + vy * t[:, None] + s * bx + c * by], -1), a))
    (c1, a1), (c2, a2) = boxes
    ok = np.ones(len(t), bool)
    for a in (a1, a1 + np.pi / 2, a2, a2 + np.pi / 2):
        axis = np.stack([np.cos(a), np.sin(a)], -1)[:, None, :]
        p1, p2 = (c1 * axis).sum(-1), (c2 * axis).sum(-1)
        ok &= (p1.max(1) >= p2.min(1)) & (p2.max(1) >= p1.min(1))
    return ok


@pytest.mark.slow
def test_first_contact_of_turning_vehicles_against_dense_sampling():
    """60 random pairs, vehicle 1 turning at up to 2 rad/s, vehicle 2 aimed at it half of the time: the
    kernel's first contact against a NumPy separating-axis test sampled every 0.2 ms over the 10 s
    horizon. Where the samples touch, the kernel found the contact, within one sample before the first
    touching one; where they never do, it reports none."""
    rng = np.random.default_rng(11)
    step = 2e-4
    ts = np.arange(0.0, G.HORIZON + step / 2, step)
    rows, refs = [], []
    for k in range(60):
        dims = [(rng.uniform(3.5, 6.0), rng.uniform(1.5, 2.2)) for _ in range(2)]
        dims = [(length, width, length * rng.uniform(0.3, 0.7)) for length, width in dims]
        x2, y2 = rng.uniform(-20, 20, 2)
        speed1, speed2 = rng.uniform(0, 20, 2)
        course1 = rng.uniform(-np.pi, np.pi)
        course2 = math.atan2(-y2, -x2) + rng.normal(0, 0.3) if k % 2 else rng.uniform(-np.pi, np.pi)
        poses = [(0.0, 0.0, rng.uniform(-np.pi, np.pi), speed1 * math.cos(course1), speed1 * math.sin(course1),
                  rng.uniform(-2, 2)),
                 (x2, y2, rng.uniform(-np.pi, np.pi), speed2 * math.cos(course2), speed2 * math.sin(course2),
                  rng.uniform(-2, 2) if k % 3 == 0 else 0.0)]
        vs = [veh(length=length, width=width, cg_to_front=front) for length, width, front in dims]
        ss = [ks_jax.State.create([x, y], yaw, velocity=[vx, vy], yaw_rate=w, cg_height=0.55)
              for x, y, yaw, vx, vy, w in poses]
        rows.append((vs[0], ss[0], vs[1], ss[1], con(0.0), 0.0))
        refs.append(_numpy_touching(dims, poses, ts))
    out = run(rows)
    touched = 0
    for k, (r, hit) in enumerate(zip(out, refs)):
        if hit.any():
            touched += 1
            assert r.contact.status != NO_CONTACT, k
            first = ts[np.argmax(hit)]
            assert first - step - 1e-9 <= r.contact.time <= first + 1e-9, (k, float(r.contact.time), first)
        else:
            assert r.contact.status == NO_CONTACT, (k, float(r.contact.time))
    assert touched >= 10  # (14 here)


def test_refine_ends_on_the_touching_side_within_its_tolerance():
    """``geometry._refine`` against roots known by hand: a curved function (root 0.3, slope -1.9 there), a
    kink just before the root (the larger of two lines, 1e-7 s apart), a triple root (slope 0: only the
    tolerance on s can end it), and a row with nothing to refine, which keeps hi."""
    tol = 1e-13
    fns = [lambda t: (0.3 - t) * (1.0 + 3.0 * t),
           lambda t: jnp.maximum(2.0 * (0.4 - t), 0.5 * (0.4 + 1e-7 - t)),
           lambda t: (0.25 - t) ** 3]
    roots, slopes = [0.3, 0.4 + 1e-7, 0.25], [1.9, 0.5, None]
    for f, root, slope in zip(fns, roots, slopes):
        lo, hi = jnp.float64(0.0), jnp.float64(0.6)
        t = float(jax.jit(lambda lo, hi: search._refine(f, lo, hi, f(lo), f(hi), tol, True))(lo, hi))
        assert -tol <= float(f(t)) <= 0.0, (root, t, float(f(t)))
        assert t >= root - 1e-15 and (slope is None or t - root <= tol / slope + 1e-15), (root, t)
        assert float(search._refine(f, lo, hi, f(lo), f(hi), tol, False)) == 0.6


@pytest.mark.slow
def test_a_scene_far_from_the_origin_gives_the_same_contact():
    """docs/model.md, "The impulse exchange": translating the scene translates the results. Survey coordinates (3e5 m)
    round at ~6e-11 m, above the geometry's ~1e-12 m tolerances: a corner meeting a turned side at the instant of
    touching (penetration_time 0) and an inline rear-end of equal widths (the collinear-edges rule) gave
    another centroid and normal there (|J| 33% and 9% off) until the geometry worked about the CGs' midpoint."""
    def box(mass, xy, yaw, speed, course=None):
        d = {"mass": mass, "inertia": [500, 2500, 2700], "length": 4, "width": 2, "height": 1.5, "cg_to_front": 2,
             "cg_height": 0.5, "position": list(xy), "yaw": yaw, "speed": speed}
        return d if course is None else dict(d, course=course)

    scenes = [
        ([box(1500, (0.0, 0.0), 20, 0), box(1500, (-1.2402544062398374, 4.869473175611347), 50, 10, -70)], 0.0),
        ([box(1500, (-3.206129905857, -9.47210277746), 251.3, 5), box(1800, (0.0, 0.0), 251.3, 15)], 0.05),
    ]
    for vehicles, dt in scenes:
        for shift in (np.array([3e5, 2.1e5]), np.array([1e4, 1e4])):
            cases = []
            for offset in (np.zeros(2), shift):
                vs = [dict(v, position=[v["position"][0] + offset[0], v["position"][1] + offset[1]]) for v in vehicles]
                cases.append(ks_jax.case.case_from_dict(
                    {"vehicles": vs, "contact": {"restitution": 0.1, "friction": 0.3, "penetration_time": dt}}))
            near, far = (ks_jax.solve(c).result for c in cases)
            assert near.contact.status == far.contact.status == OK
            np.testing.assert_allclose(far.contact.point[:2] - shift, near.contact.point[:2], atol=1e-6)
            np.testing.assert_allclose(far.contact.normal, near.contact.normal, atol=1e-6)
            np.testing.assert_allclose(far.contact.impulse, near.contact.impulse, rtol=1e-6, atol=1e-6)


@pytest.mark.slow
def test_a_touch_that_has_parted_by_the_exchange_is_refused():
    """A sideswipe by hand: a 4 m car passes a parked one 1 cm inside its side at 10 m/s, from 10 m behind;
    the footprints overlap from t = 0.6 s (front reaches rear) to 1.4 s. A penetration time of 0.5 s puts the
    exchange inside the overlap; 1.0 s puts it at 1.6 s, with the cars 2 m apart: no overlap, no centroid, so
    the row is invalid with a status naming the penetration time, and NaN results (solve and sweep alike)."""
    def box(xy, speed):
        return {"mass": 1500, "inertia": [500, 2500, 2700], "length": 4, "width": 2, "height": 1.5, "cg_to_front": 2,
                "cg_height": 0.5, "position": list(xy), "yaw": 0, "speed": speed}

    d = {"vehicles": [box((0.0, 0.0), 0.0), box((-10.0, 1.99), 10.0)],
         "contact": {"restitution": 0.1, "friction": 0.3, "penetration_time": 1.0}}
    parted = ks_jax.solve(ks_jax.case.case_from_dict(d))
    assert parted.status.startswith("invalid: contact.penetration_time is too long")
    assert np.isnan(parted.result.contact.impulse_magnitude)
    d["contact"]["penetration_time"] = 0.5
    inside = ks_jax.solve(ks_jax.case.case_from_dict(d))
    assert not inside.status.startswith("invalid") and abs(float(inside.result.contact.time) - 0.6) < TIME_TOL
    r = ks_jax.sweep(ks_jax.case.case_from_dict(d), {"contact.penetration_time": np.array([0.5, 1.0])})
    assert [ks_jax.status_text(int(s)) for s in r["status"]] == [inside.status, parted.status]


# ---------------------------------------------------------------------------------------
# the derivative in penetration_time at the touch (penetration_time = 0)


def _at_the_touch(name):
    theta = np.array(GRAD_CASES[name][0], float)
    theta[5] = 0.0
    return theta, GRAD_CASES[name][1]


def _one_sided(value, theta, base, h):
    """Second-order one-sided differences in penetration_time (>= 0) of ``value`` over AUTO's result."""
    rows = [build(jnp.asarray(theta + k * h * np.eye(len(THETA))[5]), base) for k in range(3)]
    f0, f1, f2 = (value(r) for r in run(rows))
    return (-3 * f0 + 4 * f1 - f2) / (2 * h)


@pytest.mark.slow
def test_centroid_derivative_in_penetration_time_at_the_touch_is_the_growing_triangle():
    """Oblique: vehicle 2's front-left corner touches vehicle 1's right side (y = -0.9) at (0.3, -0.9).
    After a time h the overlap is the triangle of the corner, C = (0.3, -0.9) + h (5, 10 sin60), and
    the points where its front face and its left side cross y = -0.9: (0.3 + 20 h, -0.9) and
    (0.3, -0.9) (test_oblique_corner_impact). Its centroid moves at (25/3, 10 sin60 / 3) m/s, the
    one-sided derivative at penetration_time = 0, where the overlap has no area yet (the middle of
    the touching features, which is the corner, moves at (5, 8.66 / 2)): forward and reverse mode."""
    theta, base = _at_the_touch("oblique")
    want = np.array([25.0 / 3.0, 10.0 * math.sin(OBL_YAW) / 3.0, 0.0])
    e5 = jnp.asarray(np.eye(len(THETA))[5])
    primal, tangent = jax.jvp(lambda th: build(th, base), (jnp.asarray(theta),), (e5,))
    out, tan = run_jvp(CONTACT_JVP, [primal], [jax.tree_util.tree_map(lambda x: jnp.asarray(x, float), tangent)])
    np.testing.assert_allclose(out[0][1:3], [0.3, -0.9], atol=LEN_TOL)  # at the corner
    np.testing.assert_allclose(tan[0][1:4], want, rtol=1e-6)

    def point(penetration_time):
        args = build(jnp.asarray(theta).at[5].set(penetration_time), base)
        return G.automatic_contact(*args, auto_point=True, auto_normal=True).contact.point

    np.testing.assert_allclose(reference_jit(jax.jacrev(point))(0.0), want, rtol=1e-6, atol=1e-12)  # reverse mode


@pytest.mark.parametrize("name, h", [("oblique", 1e-6), ("tbone", 1e-6), ("spin", 1e-4)])
@pytest.mark.slow
def test_result_derivatives_in_penetration_time_at_the_touch(name, h):
    """Impulse, delta-V, crush, energy, yaw rate after: d/d(penetration_time) at 0 against second-order
    one-sided differences (penetration_time >= 0). oblique: a corner into a side at 30 deg; tbone: at
    2 deg, where the triangle spreads 29 times as fast along the side as it goes in; spin: vehicle 1
    turning at 2 rad/s, where the probe of the growing overlap adds an error of the order of the angle
    turned before it (~1e-8 rad). The step h: at 1e-6 s the spinning corner's overlap is 1e-5 m wide, and
    the rounding of its crossings turns the normal by 5e-5 / s in the differences (the derivative is 0:
    the parked car's face does not turn)."""
    theta, base = _at_the_touch(name)
    e5 = jnp.asarray(np.eye(len(THETA))[5])
    primal, tangent = jax.jvp(lambda th: build(th, base), (jnp.asarray(theta),), (e5,))
    out, tan = run_jvp(AUTO_JVP, [primal], [jax.tree_util.tree_map(lambda x: jnp.asarray(x, float), tangent)])

    def value(r):
        return np.asarray(outputs(jax.tree_util.tree_map(jnp.asarray, r)))

    assert run([primal])[0].contact.status == OK
    ad, fd, f0 = np.asarray(tan[0]), _one_sided(value, theta, base, h), np.asarray(out[0])
    assert np.linalg.norm(fd[1:3]) > 1.0  # the centroid does move
    bad = np.abs(ad - fd) > 1e-5 * np.abs(fd) + 1e-7 * (1 + np.abs(f0))
    assert not np.any(bad), f"outputs {np.flatnonzero(bad)}: derivatives {ad[bad]} vs differences {fd[bad]}"


@pytest.mark.slow
def test_short_penetration_in_float32_is_the_triangle():
    """float32, the oblique corner 0.3 and 1 ms past the touch: the overlap is a triangle 2.6 and 8.7 mm
    deep (test_oblique_corner_impact), whose centroid is the impulse centroid as in float64. An overlap
    counts as having no area where it is no wider than 1e3 machine epsilons of the vehicles' size (0.5 mm
    in float32; this one is, at 0.1 ms). Before, that was where its area was below that length times the
    vehicles' size, 2e-3 m^2 in float32, and these were put at the middle of the touching features: 2.5 cm
    off at 1 ms, |J| 1% off."""
    f32 = lambda tree: jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), tree)  # noqa: E731
    auto = quick_jit(lambda args: G.automatic_exchange(*args[:5], args[5], auto_point=True, auto_normal=True))
    for dt in (3e-4, 1e-3):
        v1, s1, v2, s2, c, pitch = CASES["oblique"]
        r = auto(f32((v1, s1, v2, s2, c._replace(penetration_time=dt), pitch)))
        assert r.contact.point.dtype == jnp.float32 and int(r.contact.status) == OK
        delta = 10.0 * math.sin(OBL_YAW) * dt
        apex = np.array([0.3, -0.9]) + OBL_V * dt
        p1 = apex - delta / math.sin(OBL_YAW) * np.array([math.cos(OBL_YAW), math.sin(OBL_YAW)])
        p2 = apex + delta / math.cos(OBL_YAW) * np.array([math.sin(OBL_YAW), -math.cos(OBL_YAW)])
        centroid = (apex + p1 + p2) / 3.0
        np.testing.assert_allclose(np.asarray(r.contact.point[:2], float), centroid, atol=2e-6 + 1e-3 * delta)
        assert abs(float(r.vehicles[0].crush) - delta / 3.0) < 2e-6 + 1e-3 * delta
