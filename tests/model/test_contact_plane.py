"""The automatic contact plane (docs/model.md, "Automatic contact", "Normal"): which plane the two outline
crossings give, for offset frontals and rear-ends with partial overlap (faces that face each other: the axis
of least penetration, here the vehicles' longitudinal axis), T-bones and corners entering a side (that side),
the sign (from vehicle 2 into vehicle 1), and the exchange of an offset frontal at the normal a
reconstructionist would draw.

Every reference is hand geometry: where the vehicles are at the exchange (free motion written out), the
overlap rectangle or triangle, the struck side's outward normal. One jitted, vmapped program serves every
automatic row, one the hand exchanges, one the derivatives of the plane."""

import math

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax.compilation import quick_jit
from ks_jax.model import contact as G
from ks_jax.model.contact import contact_geometry
from ks_jax.model.types import OK

BATCH = 32
NORMAL_TOL = 1e-9
LEN_TOL = 1e-9  # m


def veh(length, width, cg_to_front, mass=1500.0, height=1.4):
    return ks_jax.Vehicle.create(mass, jnp.array([500.0, 2500.0, 2700.0]), length, width, height, cg_to_front, 0.55)


# vehicle 1 is the narrower: overlaps are fractions of its width, 1.8 m
VA = veh(4.6, 1.8, 2.1)
VB = veh(4.8, 1.9, 2.6, mass=1800.0, height=1.5)
HALF_A, HALF_B = 0.9, 0.95


def st(xy, yaw, velocity=(0.0, 0.0)):
    return ks_jax.State.create(list(xy), yaw, velocity=list(velocity), yaw_rate=0.0, cg_height=0.55)


def con(penetration_time, restitution=0.1, friction=0.5):
    return ks_jax.Contact.create(jnp.zeros(3), jnp.array([1.0, 0.0, 0.0]), restitution, friction,
                                 penetration_time=penetration_time)


def turn(v, a):
    c, s = math.cos(a), math.sin(a)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def scene(xy1, yaw1, vel1, xy2, yaw2, vel2, penetration_time, a=0.0, swap=False):
    """A row (vehicle 1, state 1, vehicle 2, state 2, contact): VA and VB as given, the whole scene turned
    by ``a`` about the origin; ``swap`` makes VB vehicle 1 and VA vehicle 2."""
    rows = [(VA, st(turn(xy1, a), yaw1 + a, turn(vel1, a))), (VB, st(turn(xy2, a), yaw2 + a, turn(vel2, a)))]
    if swap:
        rows.reverse()
    return (*rows[0], *rows[1], con(penetration_time))


def _both(v1, s1, v2, s2, c):
    """The automatic exchange and the geometry it used."""
    r = G.automatic_exchange(v1, s1, v2, s2, c, 0.0, auto_point=True, auto_normal=True)
    geo = G.automatic_contact(v1, s1, v2, s2, c, 0.0, auto_point=True, auto_normal=True).geometry
    return r, geo


AUTO = quick_jit(jax.vmap(_both))
EXCHANGE = quick_jit(jax.vmap(ks_jax.exchange))


def stack(rows):
    rows = list(rows) + [rows[0]] * (BATCH - len(rows))
    return jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *rows)


def run(rows):
    """AUTO over the rows: per row (result, geometry) as NumPy."""
    assert len(rows) <= BATCH
    out = jax.tree_util.tree_map(np.asarray, AUTO(*stack(rows)))
    return [jax.tree_util.tree_map(lambda x, i=i: x[i], out) for i in range(len(rows))]


# ---------------------------------------------------------------------------------------
# faces that face each other: offset frontals and rear-ends with partial overlap

# offset frontal: vehicle 1 at the origin heading +x at 15 m/s, vehicle 2 heading -x at 15 m/s, its CG at
# x = 10; fronts at 2.1 and 10 - 2.6 = 7.4: 5.3 m apart, closing at 30 m/s, so t_i = 5.3 / 30 s
FRONTAL_PT = 0.02  # s: 0.6 m deep, less than the overlaps of 40% and more are wide (0.72 m at 40%)
PT_20 = 0.008  # s: 0.24 m deep, for the 20% overlap, 0.36 m wide


def frontal(fraction, side, a=0.0, swap=False):
    """Offset frontal overlapping ``fraction`` of vehicle 1's width, vehicle 2 to the left (side +1) or the
    right (-1) of vehicle 1's axis. Returns the row and the hand contact at the exchange (before turning
    the scene): the time, the overlap rectangle's centroid and both crossing points."""
    pt = PT_20 if fraction < 0.4 else FRONTAL_PT
    y2 = side * (HALF_A + HALF_B - fraction * 2 * HALF_A)
    row = scene((0.0, 0.0), 0.0, (15.0, 0.0), (10.0, y2), math.pi, (-15.0, 0.0), pt, a, swap)
    t_i = 5.3 / 30.0
    t_x = t_i + pt
    front1, front2 = 2.1 + 15.0 * t_x, 7.4 - 15.0 * t_x  # the overlap is x in [front2, front1]
    edge2 = y2 - side * HALF_B  # vehicle 2's side inside vehicle 1
    edge1 = side * HALF_A  # vehicle 1's side inside vehicle 2
    centroid = np.array([0.5 * (front1 + front2), 0.5 * (edge1 + edge2)])
    # vehicle 1's front crosses vehicle 2's side; vehicle 2's front crosses vehicle 1's side
    crossings = np.array([[front1, edge2], [front2, edge1]])
    return row, t_i, t_x, centroid, crossings


# rear-end: vehicle 1 ahead at (10, 0), 5 m/s; vehicle 2 behind, 15 m/s: rear of 1 at 7.5, front of 2 at
# 2.6, 4.9 m apart at 10 m/s, so t_i = 0.49 s; 0.02 s later 0.2 m deep
def rear_end(fraction, side, a=0.0, swap=False):
    y2 = side * (HALF_A + HALF_B - fraction * 2 * HALF_A)
    row = scene((10.0, 0.0), 0.0, (5.0, 0.0), (0.0, y2), 0.0, (15.0, 0.0), 0.02, a, swap)
    t_x = 0.49 + 0.02
    rear1, front2 = 7.5 + 5.0 * t_x, 2.6 + 15.0 * t_x
    centroid = np.array([0.5 * (rear1 + front2), 0.5 * (side * HALF_A + y2 - side * HALF_B)])
    return row, 0.49, t_x, centroid


@pytest.mark.slow
def test_offset_frontals_take_the_longitudinal_normal():
    """20%, 40%, 60% and 80% of the narrower width, vehicle 2 to either side, the scene also turned
    (-70 deg, 200 deg) and the vehicles' numbers swapped: n is the longitudinal axis, from vehicle 2 into
    vehicle 1 (-x turned; +x turned when swapped), the point the overlap rectangle's centroid, and the
    crossings the rectangle's other two corners (the diagonal the plane no longer runs along)."""
    cases = [(f, s, a, w) for f in (0.2, 0.4, 0.6, 0.8) for s in (1, -1) for a, w in ((0.0, False),)]
    cases += [(f, 1, math.radians(-70.0), False) for f in (0.2, 0.6)]
    cases += [(0.4, -1, math.radians(200.0), False), (0.4, 1, 0.0, True), (0.8, -1, math.radians(33.0), True)]
    built = [frontal(*c) for c in cases]
    for (f, s, a, w), (row, t_i, t_x, centroid, crossings), (r, geo) in zip(cases, built, run([b[0] for b in built])):
        where = f"{f:.0%} overlap, side {s}, turned {math.degrees(a):.0f} deg, swapped {w}"
        assert r.contact.status == OK, where
        assert abs(r.contact.time - t_i) < 1e-9, where
        sign = 1.0 if w else -1.0
        np.testing.assert_allclose(r.contact.normal, [sign * math.cos(a), sign * math.sin(a), 0.0],
                                   atol=NORMAL_TOL, err_msg=where)
        np.testing.assert_allclose(r.contact.point[:2], turn(centroid, a), atol=LEN_TOL, err_msg=where)
        assert geo.crossing_ok and geo.facing, where
        got = sorted(map(tuple, np.round(geo.crossings, 9)))
        np.testing.assert_allclose(got, sorted(map(tuple, np.round([turn(p, a) for p in crossings], 9))),
                                   atol=1e-8, err_msg=where)


@pytest.mark.slow
def test_a_small_overlap_pushed_deeper_than_it_is_wide_keeps_the_axis_it_touched_along():
    """20% and 40% offset frontals pushed 0.9 m in, deeper than their overlaps are wide (0.36 m and 0.72 m):
    the axis of least penetration there is lateral, but the fronts first touched along the vehicles' axis,
    and the normal stays along it (from vehicle 2 into vehicle 1: -x; turned with the scene)."""
    cases = [(0.2, 1, 0.0), (0.2, -1, math.radians(40.0)), (0.4, 1, math.radians(-120.0))]
    rows = []
    for f, side, a in cases:
        y2 = side * (HALF_A + HALF_B - f * 2 * HALF_A)
        rows.append(scene((0.0, 0.0), 0.0, (15.0, 0.0), (10.0, y2), math.pi, (-15.0, 0.0), 0.03, a))
    for (f, side, a), (r, geo) in zip(cases, run(rows)):
        where = f"{f:.0%} overlap, side {side}, turned {math.degrees(a):.0f} deg"
        assert r.contact.status == OK and geo.facing, where
        np.testing.assert_allclose(r.contact.normal, [-math.cos(a), -math.sin(a), 0.0], atol=NORMAL_TOL, err_msg=where)


@pytest.mark.slow
def test_rear_ends_with_partial_overlap_take_the_longitudinal_normal():
    """30%, 50% and 80% overlap, vehicle 2 to either side, turned scenes and swapped numbers: n along the
    vehicles' axis from vehicle 2 (behind) into vehicle 1 (ahead), the point the overlap's centroid."""
    cases = [(f, s, 0.0, False) for f in (0.3, 0.5, 0.8) for s in (1, -1)]
    cases += [(0.5, 1, math.radians(30.0), False), (0.3, -1, math.radians(135.0), False),
              (0.5, -1, math.radians(-100.0), True), (0.8, 1, 0.0, True)]
    built = [rear_end(*c) for c in cases]
    for (f, s, a, w), (row, t_i, t_x, centroid), (r, geo) in zip(cases, built, run([b[0] for b in built])):
        where = f"{f:.0%} overlap, side {s}, turned {math.degrees(a):.0f} deg, swapped {w}"
        assert r.contact.status == OK, where
        assert abs(r.contact.time - t_i) < 1e-9, where
        sign = -1.0 if w else 1.0
        np.testing.assert_allclose(r.contact.normal, [sign * math.cos(a), sign * math.sin(a), 0.0],
                                   atol=NORMAL_TOL, err_msg=where)
        np.testing.assert_allclose(r.contact.point[:2], turn(centroid, a), atol=LEN_TOL, err_msg=where)
        assert geo.crossing_ok and geo.facing, where


# ---------------------------------------------------------------------------------------
# a corner or a front entering a side: the plane is that side


def tbone(heading_deg, trailing_depth=0.3, speed=10.0, t_i=0.1):
    """Vehicle 1 (VA) parked at the origin; vehicle 2 (VB) heading ``heading_deg`` into vehicle 1's right
    side (y = -0.9; from above, into its left side, y = +0.9, where the heading is negative), its front
    centre at x = 0.3 at the exchange with both front corners through that side, the trailing one by
    ``trailing_depth``. Placed so that the leading corner touches at ``t_i`` s. Returns the row, t_i and
    the normal across the struck side from vehicle 2 into vehicle 1: +y through the right side, -y through
    the left."""
    h = math.radians(heading_deg)
    side = 1.0 if math.sin(h) > 0 else -1.0  # +1: from below into the right side
    d = np.array([math.cos(h), math.sin(h)])
    lead = trailing_depth + 2 * HALF_B * abs(math.cos(h))  # the leading corner's depth through the side
    centre_y = side * (-HALF_A + trailing_depth + HALF_B * abs(math.cos(h)))
    front = np.array([0.3, centre_y])  # the front face's centre at the exchange
    pt = lead / (speed * abs(math.sin(h)))  # from the touch to the exchange
    cg = front - 2.6 * d - speed * (t_i + pt) * d
    row = (VA, st((0.0, 0.0), 0.0), VB, st(cg, h, speed * d), con(pt))
    return row, t_i, np.array([0.0, side])


def corner_into_side(heading_deg, depth=0.15, speed=10.0, t_i=0.1):
    """As ``tbone``, with only vehicle 2's leading front corner through vehicle 1's right side (the
    overlap a triangle), ``depth`` m deep, the corner at x = -1.0."""
    h = math.radians(heading_deg)
    d = np.array([math.cos(h), math.sin(h)])
    left = np.array([-math.sin(h), math.cos(h)])
    lead_sign = 1.0 if math.cos(h) > 0 else -1.0  # the front-left corner leads where heading right
    corner = np.array([-1.0, -HALF_A + depth])
    front = corner - lead_sign * HALF_B * left
    pt = depth / (speed * math.sin(h))
    cg = front - 2.6 * d - speed * (t_i + pt) * d
    return (VA, st((0.0, 0.0), 0.0), VB, st(cg, h, speed * d), con(pt)), t_i


def corner_into_side_of_2(yaw2_deg=110.0, depth_x=0.3, speed=10.0, t_i=0.1):
    """Vehicle 2 (VB) parked at the origin, yawed ``yaw2_deg`` (its left side facing -x, turned 20 deg);
    vehicle 1 (VA) heading +x at ``speed``, its front-left corner through that side by ``depth_x`` along x
    at the exchange, entering at vehicle 2's body x = 0. The plane is vehicle 2's left side: n its outward
    normal (-sin yaw2, cos yaw2), pointing at vehicle 1."""
    p = math.radians(yaw2_deg)
    outward = np.array([-math.sin(p), math.cos(p)])
    touch = HALF_B * outward
    pt = depth_x / speed
    cg = touch - np.array([2.1, HALF_A]) - np.array([speed * t_i, 0.0])
    row = (VA, st(cg, 0.0, (speed, 0.0)), VB, st((0.0, 0.0), p), con(pt))
    return row, t_i, outward


@pytest.mark.slow
def test_tbones_and_corners_take_the_struck_side():
    """T-bones at 60, 90 and 120 deg into the right side and at -90 and -120 deg into the left, corners
    entering the right side at 30, 45 and 135 deg, and vehicle 1's corner entering vehicle 2's turned left
    side: n is the struck side's normal, pointing from vehicle 2 into vehicle 1, and the plane comes from
    both crossings lying on that side (not facing faces)."""
    rows, want = [], []
    for a in (60.0, 90.0, 120.0, -90.0, -120.0):
        row, t_i, n = tbone(a)
        rows.append(row)
        want.append((f"T-bone at {a} deg", t_i, n))
    for a in (30.0, 45.0, 135.0):
        row, t_i = corner_into_side(a)
        rows.append(row)
        want.append((f"corner into the side at {a} deg", t_i, np.array([0.0, 1.0])))
    row, t_i, outward = corner_into_side_of_2()
    rows.append(row)
    want.append(("vehicle 1's corner into vehicle 2's side", t_i, outward))
    for (where, t_i, n), (r, geo) in zip(want, run(rows)):
        assert r.contact.status == OK, where
        assert abs(r.contact.time - t_i) < 1e-9, where
        np.testing.assert_allclose(r.contact.normal, [n[0], n[1], 0.0], atol=NORMAL_TOL, err_msg=where)
        assert geo.crossing_ok and not geo.facing, where
        # both crossings on the struck side's line: the chord lies along it
        chord = geo.crossings[1] - geo.crossings[0]
        assert abs(chord @ n) < 1e-9 * np.linalg.norm(chord), where


def test_tbone_at_90_deg_by_hand():
    """The 90 deg T-bone's overlap: vehicle 2's front, 1.9 m wide about x = 0.3, 0.3 m through y = -0.9;
    the centroid is the rectangle's, the crush of each half its depth along n."""
    row, _, _ = tbone(90.0)
    ((r, geo),) = run([row])
    np.testing.assert_allclose(r.contact.point, [0.3, -0.9 + 0.15, 0.7], atol=LEN_TOL)
    np.testing.assert_allclose(np.sort(geo.crossings[:, 0]), [0.3 - HALF_B, 0.3 + HALF_B], atol=LEN_TOL)
    np.testing.assert_allclose(geo.crossings[:, 1], [-0.9, -0.9], atol=LEN_TOL)
    np.testing.assert_allclose([v.crush for v in r.vehicles], [0.15, 0.15], atol=LEN_TOL)


# ---------------------------------------------------------------------------------------
# the exchange of the 40% offset frontal


def _advanced(state, t):
    return state._replace(position=state.position + state.velocity * t)


@pytest.mark.slow
def test_forty_percent_offset_frontal_sticks_at_the_longitudinal_normal():
    """The 40% offset frontal, 0.6 m deep: the automatic exchange is ``ks_jax.exchange`` with both vehicles
    moved by hand to the exchange and the contact drawn by hand (the overlap's centroid, n = -x) to 1e-9,
    and it sticks (mu = 0.5). At the old plane, along the overlap's diagonal (n perpendicular to the line
    through the crossings: 0.72 m across and 0.6 m deep), the same centroid gives a sliding exchange and
    a smaller impulse."""
    (v1, s1, v2, s2, c), _, t_x, centroid, crossings = frontal(0.4, 1)
    ((r, geo),) = run([(v1, s1, v2, s2, c)])
    assert geo.facing
    point = [centroid[0], centroid[1], 0.7]
    chord = crossings[1] - crossings[0]
    diag = np.array([-chord[1], chord[0]]) / np.linalg.norm(chord)
    diag = diag if diag[0] < 0 else -diag  # from vehicle 2 (ahead) into vehicle 1
    rows = [(v1, _advanced(s1, t_x), v2, _advanced(s2, t_x), c._replace(point=jnp.asarray(point), normal=n))
            for n in (jnp.array([-1.0, 0.0, 0.0]), jnp.array([diag[0], diag[1], 0.0]))]
    out = EXCHANGE(*stack(rows))
    hand, old = (jax.tree_util.tree_map(lambda x, i=i: np.asarray(x)[i], out) for i in range(2))
    for name in ("impulse", "energy_loss", "closing_velocity", "separation_velocity", "sliding"):
        a, b = getattr(r.contact, name), getattr(hand.contact, name)
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * (1 + np.max(np.abs(b))), err_msg=name)
    for k in range(2):
        for name in ("delta_v", "angular_velocity_after", "crush", "ees", "pdof"):
            a, b = getattr(r.vehicles[k], name), getattr(hand.vehicles[k], name)
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * (1 + np.max(np.abs(b))), err_msg=name)
    assert not r.contact.sliding and bool(old.contact.sliding)
    assert r.contact.impulse_magnitude > 1.05 * old.contact.impulse_magnitude
    # the old normal was 39.8 deg off the axis: the rectangle 0.72 m across and 0.6 m deep
    assert math.degrees(math.acos(-diag[0])) == pytest.approx(math.degrees(math.atan2(0.6, 0.72)), abs=1e-9)


# ---------------------------------------------------------------------------------------
# derivatives of the plane


def _normal_of(theta, row):
    """contact_geometry's normal (2,) of ``row``'s vehicles where they stand, with vehicle 1's yaw and
    vehicle 2's yaw, x and y moved by theta (4,)."""
    v1, s1, v2, s2, _ = row
    s1 = s1._replace(yaw=s1.yaw + theta[0])
    s2 = s2._replace(yaw=s2.yaw + theta[1], position=s2.position + jnp.stack([theta[2], theta[3], 0.0 * theta[3]]))
    return contact_geometry(v1, s1, v2, s2).normal[:2]


NORMAL_JAC = quick_jit(jax.vmap(jax.jacfwd(_normal_of), in_axes=(None, 0)))


@pytest.mark.slow
def test_the_planes_derivatives():
    """d n / d (yaw 1, yaw 2, x 2, y 2) where the vehicles stand at the exchange. The T-bone's n is vehicle
    1's right-side normal (-sin yaw1, cos yaw1): (-1, 0) per radian of yaw 1, nothing else. The offset
    frontal with vehicle 2 turned 8 deg: n is one of the fronts' axes, whichever is penetrated less (found
    by hand projections), and it turns with that vehicle's yaw only: not with the positions, as the
    diagonal did."""
    tb_row, t_i, _ = tbone(90.0)
    t_x = t_i + float(tb_row[4].penetration_time)
    tb = (tb_row[0], _advanced(tb_row[1], t_x), tb_row[2], _advanced(tb_row[3], t_x), tb_row[4])
    # an offset frontal, vehicle 2 turned 8 deg off head-on, overlapping where it stands
    yaw2, xy2 = math.pi + math.radians(8.0), (2.1 + 2.6 - 0.3, 1.0)
    fr = (VA, st((0.0, 0.0), 0.0), VB, st(xy2, yaw2), con(0.0))
    jac = np.asarray(NORMAL_JAC(jnp.zeros(4), stack([tb, fr])))[:2]
    np.testing.assert_allclose(jac[0], [[-1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]], atol=1e-12)

    def corners(length, width, cg_to_front, xy, yaw):
        bx = np.array([cg_to_front - length, cg_to_front, cg_to_front, cg_to_front - length])
        by = np.array([-width / 2, -width / 2, width / 2, width / 2])
        c, s = math.cos(yaw), math.sin(yaw)
        return np.stack([xy[0] + c * bx - s * by, xy[1] + s * bx + c * by], -1)

    c1, c2 = corners(4.6, 1.8, 2.1, (0.0, 0.0), 0.0), corners(4.8, 1.9, 2.6, xy2, yaw2)
    axes = {"yaw1": np.array([1.0, 0.0]), "lat1": np.array([0.0, 1.0]),
            "yaw2": np.array([math.cos(yaw2), math.sin(yaw2)]), "lat2": np.array([-math.sin(yaw2), math.cos(yaw2)])}
    depth = {k: min((c1 @ a).max(), (c2 @ a).max()) - max((c1 @ a).min(), (c2 @ a).min()) for k, a in axes.items()}
    least = min(depth, key=depth.get)
    assert least in ("yaw1", "yaw2")  # a front's axis
    n = axes[least] if axes[least] @ (c1.mean(0) - c2.mean(0)) > 0 else -axes[least]
    ((r, geo),) = run([fr])
    assert geo.facing  # parked: the exchange itself is 'separating'
    np.testing.assert_allclose(r.contact.normal[:2], n, atol=NORMAL_TOL)
    want = np.zeros((2, 4))
    want[:, 0 if least == "yaw1" else 1] = [-n[1], n[0]]  # a unit vector turned with that vehicle
    np.testing.assert_allclose(jac[1], want, atol=1e-12)
