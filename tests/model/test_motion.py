"""The motion to rest (``ks_jax.model.motion``) against closed forms, conservation and finite differences
(docs/model.md, "Motion to rest").

Each check batches its cases into one vmapped call, so that the module compiles a few programs only, with the
quick settings (``samples.reference_jit``: the same arithmetic, half the compile time)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ks_jax.model import motion as M
from ks_jax.model import motion_loop as ML
from ks_jax.units import G0
from samples import reference_jit

MASS, IZZ, CG_HEIGHT = 1500.0, 2500.0, 0.55
# the CG midway between the axles: the spin in place has no resultant force
CENTRED = M.Chassis(jnp.asarray(2.8), jnp.asarray(1.6), jnp.asarray(1.4))
FORWARD = M.Chassis(jnp.asarray(2.8), jnp.asarray(1.6), jnp.asarray(1.15))
LOCKED = [1.0, 1.0, 1.0, 1.0]
FREE = [0.0, 0.0, 0.0, 0.0]


def _wheels(brake, steer=0.0, f=0.015):
    return M.Wheels(jnp.asarray(brake, float), jnp.asarray(steer, float), jnp.asarray(f, float))


def _start(vx, vy=0.0, r=0.0, yaw=0.0):
    return M.Planar(jnp.zeros(2), jnp.asarray(yaw, float), jnp.asarray([vx, vy], float), jnp.asarray(r, float))


def _batch(items):
    """Stacked in NumPy (a jnp.stack of each number of rows would compile a program of its own)."""
    return jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x, float) for x in xs]), *items)


ROWS = 4  # every batch of ``_rest_many`` padded to this many rows: one program per settings, whatever the cases


def _rest_many(chassis, wheels, friction, starts, dt=M.TIME_STEP, limit=M.TIME_LIMIT, reverse=False):
    """``to_rest`` of each row of (chassis, wheels, friction, start), in one vmapped program per settings (the
    rows padded to ``ROWS`` by repeating the first), as NumPy arrays of the given rows."""
    n = len(starts)
    assert n <= ROWS
    pad = lambda items: list(items) + [items[0]] * (ROWS - n)  # noqa: E731
    args = _batch(pad(chassis)), _batch(pad(wheels)), np.asarray(pad(list(friction)), float), _batch(pad(starts))
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[:n], _compiled(dt, limit, reverse)(*args))


_PROGRAMS = {}


def _compiled(dt, limit, reverse):
    key = (dt, limit, reverse)
    if key not in _PROGRAMS:
        _PROGRAMS[key] = reference_jit(jax.vmap(lambda c, w, mu, s: ML.to_rest(MASS, IZZ, CG_HEIGHT, c, w, mu, s, dt=dt,
                                                                          time_limit=limit, reverse=reverse)))
    return _PROGRAMS[key]


SKIDS = [(30.0, 0.8), (10.0, 0.7), (3.0, 0.3), (22.0, 1.0)]  # (speed m/s, friction)


@pytest.mark.slow
def test_locked_straight_skid_stops_at_the_closed_form_distance_and_time():
    """All four wheels locked, no yaw rate: d = v^2 / (2 mu g), t = v / (mu g), straight; 1e-3 relative at the
    default step (both the forward loop and the reverse-ready scan)."""
    n = len(SKIDS)
    for reverse in (False, True):
        r = _rest_many([FORWARD] * n, [_wheels(LOCKED)] * n, [mu for _, mu in SKIDS],
                       [_start(v, yaw=0.0) for v, _ in SKIDS], limit=5.0, reverse=reverse)
        for k, (v, mu) in enumerate(SKIDS):
            d, t = v * v / (2 * mu * G0), v / (mu * G0)
            np.testing.assert_allclose(float(r.rest_position[k, 0]), d, rtol=1e-3)
            np.testing.assert_allclose(float(r.distance_to_rest[k]), d, rtol=1e-3)
            np.testing.assert_allclose(float(r.time_to_rest[k]), t, rtol=1e-3)
            assert abs(float(r.rest_position[k, 1])) < 1e-9 and abs(float(r.rotation_to_rest[k])) < 1e-9
            assert bool(r.at_rest[k])


def test_free_rolling_coast_stops_at_the_closed_form_distance_or_moves_on_at_the_time_limit():
    """All wheels free, straight: rolling resistance only, d = v^2 / (2 f g), t = v / (f g). A coast longer than the
    time limit (60.003 s: 12001 steps, not a whole number of the loop's chunks) is not at rest, and has moved for
    exactly the limit's steps at constant deceleration."""
    cases = [(8.0, 0.015), (5.0, 0.02), (15.0, 0.015)]
    r = _rest_many([FORWARD] * 3, [_wheels(FREE, f=f) for _, f in cases], [0.7] * 3,
                   [_start(v) for v, _ in cases], limit=60.003)
    for k, (v, f) in enumerate(cases[:2]):
        np.testing.assert_allclose(float(r.rest_position[k, 0]), v * v / (2 * f * G0), rtol=1e-3)
        np.testing.assert_allclose(float(r.time_to_rest[k]), v / (f * G0), rtol=1e-3)
        assert bool(r.at_rest[k])
    t = 12001 * M.TIME_STEP
    assert not bool(r.at_rest[2]) and float(r.time_to_rest[2]) == pytest.approx(t, rel=1e-12)
    np.testing.assert_allclose(float(r.rest_position[2, 0]), 15.0 * t - 0.5 * 0.015 * G0 * t * t, rtol=1e-6)


def test_locked_spin_in_place_stops_at_the_closed_form_time_without_moving_the_cg():
    """All four locked, spinning in place with the CG midway between the axles: the wheel forces have no
    resultant, so the CG stays put, and t = Izz r0 / (mu g m rho), rho the wheels' distance from the CG; the
    yaw turned is r0 t / 2 (a constant angular deceleration)."""
    rho = math.hypot(1.4, 0.8)
    spins = [(3.0, 0.7), (-5.0, 0.9)]
    r = _rest_many([CENTRED] * 2, [_wheels(LOCKED)] * 2, [mu for _, mu in spins],
                   [_start(0.0, r=r0) for r0, _ in spins], limit=5.0)
    for k, (r0, mu) in enumerate(spins):
        t = IZZ * abs(r0) / (mu * G0 * MASS * rho)
        np.testing.assert_allclose(float(r.time_to_rest[k]), t, rtol=1e-3)
        np.testing.assert_allclose(float(r.rotation_to_rest[k]), math.degrees(0.5 * r0 * t), rtol=1e-3)
        assert np.max(np.abs(np.asarray(r.rest_position[k]))) < 1e-9


@pytest.mark.slow
def test_closed_forms_hold_at_every_step_and_a_general_motion_converges_as_the_step_shrinks():
    """The closed forms to 1e-3 at steps from 20 ms to 2.5 ms; a spinning, sliding vehicle with its fronts
    braked (no closed form) converges: the rest position's change from one step to half of it shrinks (first
    order: about halves)."""
    general = (FORWARD, _wheels([1.0, 1.0, 0.0, 0.0]), 0.7, _start(12.0, 2.0, 1.5))
    skid = (FORWARD, _wheels(LOCKED), 0.7, _start(15.0))
    positions = []
    for dt in (0.02, 0.01, 0.005, 0.0025):
        r = _rest_many(*zip(general, skid), dt=dt, limit=6.0)
        np.testing.assert_allclose(float(r.rest_position[1, 0]), 15.0 ** 2 / (2 * 0.7 * G0), rtol=1e-3)
        positions.append(np.asarray(r.rest_position[0]))
    changes = [np.linalg.norm(b - a) for a, b in zip(positions, positions[1:])]
    assert all(later < 0.75 * earlier for earlier, later in zip(changes, changes[1:])), changes
    assert changes[-1] < 0.01


def _energies(chassis, wheels, friction, start, n):
    """The kinetic energy at the start and after each of n steps (``motion.step`` itself)."""
    m = jnp.array([MASS, MASS, IZZ])

    def one(c, _):
        c = M.step(MASS, IZZ, CG_HEIGHT, chassis, wheels, friction, c, M.TIME_STEP)
        q = jnp.stack([c.state.velocity[0], c.state.velocity[1], c.state.yaw_rate])
        return c, 0.5 * jnp.sum(m * q * q)

    carry = M.start_carry(start)
    q0 = jnp.stack([start.velocity[0], start.velocity[1], start.yaw_rate])
    return jnp.concatenate([(0.5 * jnp.sum(m * q0 * q0))[None], jax.lax.scan(one, carry, None, length=n)[1]])


ENERGIES = reference_jit(_energies, static_argnums=4)  # one program for every case below


@pytest.mark.parametrize("brake, steer, start", [
    (LOCKED, 0.0, (12.0, 3.0, 2.5)),
    ([0.3, 0.3, 0.0, 0.0], 0.1, (15.0, -4.0, -3.0)),
    (FREE, -0.2, (9.0, 6.0, 4.0)),
])
def test_kinetic_energy_never_increases(brake, steer, start):
    """Friction only takes energy: at every step, sliding, rolling or spinning, the kinetic energy is at most the
    step before's (to rounding)."""
    e = np.asarray(ENERGIES(FORWARD, _wheels(brake, steer), 0.8, _start(*start), 1200))
    assert e[0] > 0 and np.all(np.diff(e) <= 1e-9 * e[0]), np.diff(e).max()


def test_a_spinning_locked_vehicle_slides_between_its_straight_skid_and_its_energy_skid_distances():
    """All four locked with a yaw rate. The wheels' friction forces, mu Fz each against its wheel's velocity, have a
    resultant of at most mu m g: the CG slows at most as fast as in a straight skid, so its path is at least
    d = v^2 / (2 mu g) long. And the friction's power, sum mu Fz |w_i|, is at least mu |sum Fz w_i| = mu m g |v|
    (the loads' centre is the CG): the kinetic energy E0 falls by at least mu m g per metre of the CG's path, which
    is at most E0 / (mu m g). The straight line from start to rest is no longer than the path."""
    starts = [_start(15.0, 0.0, r) for r in (1.0, 3.0, -6.0)] + [_start(8.0, 5.0, 4.0)]
    r = _flat_many([FORWARD] * 4, [_wheels(LOCKED)] * 4, [0.7] * 4, starts)
    for k, s in enumerate(starts):
        v2 = float(jnp.sum(s.velocity ** 2))
        skid, energy = v2 / (2 * 0.7 * G0), (v2 + IZZ / MASS * float(s.yaw_rate) ** 2) / (2 * 0.7 * G0)
        path = float(r.distance_to_rest[k])
        assert bool(r.at_rest[k]) and abs(float(r.rotation_to_rest[k])) > 1.0  # it turned as it slid
        assert skid * (1 - 1e-3) <= path <= energy * (1 + 1e-3), (skid, path, energy)
        assert float(jnp.linalg.norm(r.rest_position[k])) <= path * (1 + 1e-9)


def _flat_many(chassis, wheels, friction, starts):
    """``_rest_many`` with the CG at the ground: no load transfer, so that the loads' centre stays at the CG."""
    args = _batch(chassis), _batch(wheels), jnp.asarray(friction, float), _batch(starts)
    return reference_jit(jax.vmap(lambda c, w, mu, s: ML.to_rest(MASS, IZZ, 0.0, c, w, mu, s, time_limit=8.0)))(*args)


def _rest_xy(params, reverse=False):
    """Rest x, y of one motion as a function of (vx, vy, yaw rate, friction, front brake, steer)."""
    vx, vy, yaw_rate, mu, brake, steer = params
    wheels = M.Wheels(jnp.stack([brake, brake, 0.0 * brake, 0.0 * brake]), steer, jnp.asarray(0.015))
    start = M.Planar(jnp.zeros(2), jnp.asarray(0.3), jnp.stack([vx, vy]), yaw_rate)
    return ML.to_rest(MASS, IZZ, CG_HEIGHT, FORWARD, wheels, mu, start, time_limit=4.0, reverse=reverse).rest_position


@pytest.mark.slow
def test_rest_position_gradients_match_central_differences_forward_and_reverse():
    """d(rest x, y)/d(speeds, yaw rate, friction, brake, steer) by ``jax.jacfwd`` (the forward loop) and by
    ``jax.jacrev`` (the reverse-ready scan) against central differences, and the two modes against each other."""
    p = jnp.array([12.0, 2.0, 1.2, 0.75, 0.6, 0.05])
    fwd = np.asarray(reference_jit(jax.jacfwd(_rest_xy))(p))
    rev = np.asarray(reference_jit(jax.jacrev(lambda q: _rest_xy(q, reverse=True)))(p))
    f = reference_jit(_rest_xy)
    h = np.array([1e-4, 1e-4, 1e-5, 1e-6, 1e-6, 1e-6])
    fd = np.stack([(np.asarray(f(p.at[k].add(h[k]))) - np.asarray(f(p.at[k].add(-h[k])))) / (2 * h[k])
                   for k in range(len(p))], axis=1)
    np.testing.assert_allclose(fwd, fd, rtol=2e-3, atol=2e-3 * np.abs(fd).max())
    np.testing.assert_allclose(rev, fwd, rtol=1e-9, atol=1e-9 * np.abs(fwd).max())
    assert np.all(np.isfinite(fwd))


# one step's states that take each branch of the step: (brake, steer, friction, f, velocity, yaw rate, accel)
STEP_STATES = [
    (LOCKED, 0.0, 0.8, 0.015, (14.0, 3.0), 1.1, (-6.0, 2.0)),  # sliding, yawing
    ([0.3, 0.7, 0.0, 1.0], -0.08, 0.6, 0.015, (-4.0, 9.0), -0.6, (1.0, -3.0)),  # braked by fractions
    (FREE, 0.05, 0.9, 0.015, (20.0, -1.5), 0.3, (0.5, 4.0)),  # rolling, with slip
    (FREE, 0.0, 0.7, 0.7, (8.0, 2.0), 0.4, (0.0, 1.0)),  # no lateral grip left by rolling resistance
    (LOCKED, 0.0, 0.7, 0.015, (3.0, -5.0), 0.8, (-9.0, 12.0)),  # load transfer lifting a wheel
    (LOCKED, 0.0, 0.75, 0.015, (0.02, 0.01), 0.01, (0.0, 0.0)),  # stops in this step (phi < 1)
    (FREE, 0.12, 0.55, 0.015, (0.01, 0.006), -0.007, (5.9, -1.6)),  # moving, its change scaled back
]


@pytest.mark.slow
def test_reverse_scans_step_adjoint_matches_jaxs_own_vjp_on_every_branch():
    """The reverse-ready scan's step carries a hand-written adjoint (``_step_reverse``); at states that take each
    branch of the step (sliding, braked, rolling, no grip, a lifted wheel, stopping within the step, a change
    scaled back by the energy rule), its vector-Jacobian product for random cotangents equals JAX's own of the
    same step, for every input of the body and the carry."""
    def parts(brake, steer, mu, f, velocity, yaw_rate, accel):
        b = M.body(MASS, IZZ, CG_HEIGHT, FORWARD, _wheels(brake, steer, f), mu, M.TIME_STEP)
        start = M.Planar(jnp.asarray([1.0, -2.0]), jnp.asarray(0.3), jnp.asarray(velocity, float),
                         jnp.asarray(yaw_rate, float))
        one = jnp.asarray(1.0)
        return b, M.Carry(start, jnp.asarray(accel, float), 2.0 * one, 5.0 * one, one)

    bodies, carries = zip(*(parts(*state) for state in STEP_STATES))
    b, carry = _batch(bodies), _batch(carries)
    rng = np.random.default_rng(7)
    cotangent = jax.tree_util.tree_map(lambda x: jnp.asarray(rng.normal(size=x.shape)), carry)

    def vjps(b, carry, ct):
        own = jax.vjp(lambda b, c: M._step(b, c, M.TIME_STEP), b, carry)[1](ct)
        hand = jax.vjp(lambda b, c: M._step_reverse(b, c, M.TIME_STEP), b, carry)[1](ct)
        return own, hand, M._advance(b, carry, M.TIME_STEP)[1]

    own, hand, saved = reference_jit(jax.vmap(vjps))(b, carry, cotangent)
    phi, raw, loads = np.asarray(saved.phi), np.asarray(saved.raw), np.asarray(saved.loads)
    assert np.any(phi < 1) and np.any((phi >= 1) & (raw > 0) & (raw < 1)) and np.any(loads == 0)  # the branches
    for (path, want), got in zip(jax.tree_util.tree_flatten_with_path(own)[0], jax.tree_util.tree_leaves(hand)):
        want, got = np.asarray(want), np.asarray(got)
        scale = np.abs(want).reshape(len(STEP_STATES), -1).max(axis=1).reshape((-1,) + (1,) * (want.ndim - 1))
        bad = np.abs(got - want) > 1e-9 * (np.abs(want) + scale) + 1e-15
        assert not np.any(bad), (jax.tree_util.keystr(path), got[bad], want[bad])


@pytest.mark.slow
def test_a_change_below_rounding_next_to_the_velocities_has_finite_forward_derivatives():
    """A car rolling straight on at 0.5 m/s, free wheels without rolling resistance, with a lateral velocity of
    1e-100 m/s or a yaw rate of 1e-60 rad/s (the tyres damp a yaw rate geometrically toward 0): its step's whole
    change is far below rounding next to its velocity, and the energy rule's quotient, whose derivative goes as
    1 / (dq m dq)^2, must not be taken there. The step's forward-mode Jacobian in the velocities is finite and
    equals the one at a lateral velocity and yaw rate of exactly 0, their limit."""
    b = M.body(MASS, IZZ, CG_HEIGHT, FORWARD, _wheels(FREE, f=0.0), 0.8, M.TIME_STEP)

    def jacobian(vy, r):
        zero = 0.0 * vy

        def new(q):
            carry = M.Carry(M.Planar(jnp.zeros(2), zero, q[:2], q[2]), jnp.zeros(2), zero, zero, 1.0 + zero)
            state = M._step(b, carry, M.TIME_STEP).state
            return jnp.concatenate([state.velocity, state.yaw_rate[None]])
        return jax.jacfwd(new)(jnp.stack([0.5 + zero, vy, r]))

    *tiny, zero = np.asarray(reference_jit(jax.vmap(jacobian))(jnp.asarray([1e-100, 0.0, 0.0]),
                                                                jnp.asarray([0.0, 1e-60, 0.0])))
    for jac in tiny:
        assert np.all(np.isfinite(jac)), jac
        np.testing.assert_allclose(jac, zero, rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_jit_vmap_and_one_row_agree_and_every_result_is_finite_at_rest():
    """A batch (vmap, in one program) gives each row what the row gives alone, unbatched; a vehicle at rest from
    the start has time and distance 0, its yaw unchanged, and finite gradients."""
    starts = [_start(12.0, 2.0, 1.5, 0.2), _start(0.0, 0.0, 0.0, 1.0), _start(6.0, -1.0, -2.0, -0.4)]
    wheels = [_wheels([1, 1, 0, 0]), _wheels(LOCKED), _wheels([0.2, 0.2, 0.5, 0.5], 0.1)]
    batched = _rest_many([FORWARD] * 3, wheels, [0.7, 0.7, 0.9], starts, limit=6.0)

    def checks(w, mu, s, v):
        """One program (one compile): a row alone, and the gradient of a motion at rest from the start."""
        return (ML.to_rest(MASS, IZZ, CG_HEIGHT, FORWARD, w, mu, s, time_limit=6.0),
                jax.grad(lambda v: jnp.sum(ML.to_rest(MASS, IZZ, CG_HEIGHT, FORWARD, _wheels(LOCKED), 0.7, _start(v),
                                                     time_limit=2.0, reverse=True).rest_position))(v))

    one = reference_jit(checks)
    for k in range(3):
        alone, grad = one(wheels[k], jnp.asarray([0.7, 0.7, 0.9][k]), starts[k], 0.0)
        for name in ("rest_position", "rest_yaw", "time_to_rest", "distance_to_rest"):
            np.testing.assert_allclose(np.asarray(getattr(batched, name)[k]), np.asarray(getattr(alone, name)),
                                       rtol=1e-9, atol=1e-9, err_msg=name)
    assert float(batched.time_to_rest[1]) == 0 and float(batched.distance_to_rest[1]) == 0
    np.testing.assert_allclose(float(batched.rest_yaw[1]), math.degrees(1.0), rtol=1e-12)
    assert np.isfinite(float(grad))


def test_wheel_loads_sum_to_the_weight_and_transfer_as_the_moments_say():
    """Static loads split by axle in the ratio of the CG's distances; braking (a < 0) moves m a h / L to the front
    axle, turning left (lateral a > 0) moves m a h / t to the right wheels; a lifted wheel carries 0."""
    chassis, weight = FORWARD, MASS * G0
    a, L, t = 1.15, 2.8, 1.6
    static = np.asarray(M.wheel_loads(MASS, CG_HEIGHT, chassis, jnp.zeros(2)))
    np.testing.assert_allclose(static, [weight * (L - a) / L / 2] * 2 + [weight * a / L / 2] * 2, rtol=1e-12)
    braking = np.asarray(M.wheel_loads(MASS, CG_HEIGHT, chassis, jnp.array([-6.0, 0.0])))
    np.testing.assert_allclose(braking[:2].sum() - static[:2].sum(), MASS * 6.0 * CG_HEIGHT / L, rtol=1e-12)
    turning = np.asarray(M.wheel_loads(MASS, CG_HEIGHT, chassis, jnp.array([0.0, 3.0])))
    np.testing.assert_allclose(turning[[1, 3]].sum() - static[[1, 3]].sum(), MASS * 3.0 * CG_HEIGHT / t, rtol=1e-12)
    lifted = np.asarray(M.wheel_loads(MASS, CG_HEIGHT, chassis, jnp.array([0.0, 30.0])))
    assert lifted[0] == 0 and lifted[2] == 0
    for loads in (braking, turning, lifted):
        np.testing.assert_allclose(loads.sum(), weight, rtol=1e-12)


@pytest.mark.slow
def test_every_tyre_force_stays_inside_its_friction_circle():
    """|F| <= mu Fz for free, locked and braked wheels, at any slip, with the friction left after rolling
    resistance; a locked wheel's force opposes its velocity."""
    rng = np.random.default_rng(4)
    v = rng.normal(0, 8, (200, 4, 2))
    loads = rng.uniform(0, 6000, (200, 4))
    brake = rng.uniform(0, 1, (200, 4))
    brake[:50], brake[50:100] = 1.0, 0.0
    # jitted: one program (run eagerly, each operation would compile one)
    force, _ = reference_jit(jax.vmap(lambda w, fz, b: M.tyre_forces(w, fz, _wheels(b), 0.8, M.TIME_STEP)))(
        v, loads, brake)
    size = np.linalg.norm(np.asarray(force), axis=-1)
    assert np.all(size <= 0.8 * np.asarray(loads) * (1 + 1e-12))
    locked = np.asarray(force[:50])
    cosine = np.sum(locked * np.asarray(v[:50]), -1) / (size[:50] * np.linalg.norm(np.asarray(v[:50]), axis=-1))
    np.testing.assert_allclose(cosine, -1.0, atol=1e-6)
