"""The approach before the impact (``ks_jax.model.approach``), worked back from the impact state, against closed
forms (a locked straight skid by its distance or its duration, free rolling), the motion's own steps run forward
again from the approach's start, and finite differences of its derivatives in both modes (docs/model.md, "The
approach").

Each check batches its rows into one vmapped call of a program compiled with the quick settings
(``samples.reference_jit``)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ks_jax.model import motion as M
from ks_jax.model.approach import PHASE_STEPS, Phases, approach
from ks_jax.units import G0
from samples import reference_jit

MASS, IZZ, CG_HEIGHT = 1500.0, 2500.0, 0.55
CHASSIS = M.Chassis(jnp.asarray(2.7), jnp.asarray(1.55), jnp.asarray(1.2))


def phases(brakes, frictions, lengths, f=0.015, steer=0.0):
    """Phases of all four wheels braked by each of ``brakes`` (one per phase, earliest first)."""
    return Phases(M.Wheels(np.array([[b] * 4 for b in brakes], float), np.full(len(brakes), steer, float),
                           np.full(len(brakes), f, float)),
                  np.asarray(frictions, float), np.asarray(lengths, float))


def impact(vx, vy=0.0, r=0.0, yaw=0.0, x=0.0, y=0.0):
    return M.Planar(np.array([x, y], float), np.asarray(yaw, float), np.array([vx, vy], float), np.asarray(r, float))


def _stack(items):
    return jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x, float) for x in xs]), *items)


@functools.cache
def _program(kinds, path=False):
    return reference_jit(jax.vmap(lambda p, s: approach(MASS, IZZ, CG_HEIGHT, CHASSIS, p, kinds, s, path=path)))


def run(kinds, rows, path=False):
    """``approach`` of every (phases, impact) row at once, as NumPy arrays."""
    out = _program(tuple(kinds), path)(_stack([p for p, _ in rows]), _stack([s for _, s in rows]))
    return jax.tree_util.tree_map(np.asarray, out)


@pytest.mark.slow
def test_a_locked_straight_skid_by_its_distance_is_the_closed_form():
    """Every wheel locked over a skid of d before an impact at v, straight: v_start = sqrt(v^2 + 2 mu g d), the skid's
    time (v_start - v) / (mu g), its start d behind the impact along the heading (heading 30 deg, at (4, -2) m); a
    skid of 0 m is the impact itself."""
    cases = [(15.0, 0.7, 20.0), (25.0, 0.45, 35.0), (3.0, 0.8, 8.0), (12.0, 0.7, 0.0)]
    heading = np.radians(30.0)
    u = np.array([np.cos(heading), np.sin(heading)])
    rows = [(phases([1.0], [mu], [d]), impact(*(v * u), yaw=heading, x=4.0, y=-2.0)) for v, mu, d in cases]
    out = run(("distance",), rows)
    for k, (v, mu, d) in enumerate(cases):
        start = np.sqrt(v * v + 2 * mu * G0 * d)
        assert out.speed[k, 0] == pytest.approx(start, rel=1e-5)
        assert out.time[k, 0] == pytest.approx(-(start - v) / (mu * G0), abs=1e-5)
        assert out.distance[k, 0] == pytest.approx(d, abs=1e-6)
        np.testing.assert_allclose(out.position[k, 0], np.array([4.0, -2.0]) - d * u, atol=1e-5)
        assert out.yaw[k, 0] == pytest.approx(30.0, abs=1e-9)


@pytest.mark.slow
def test_locked_and_free_phases_by_duration_are_the_closed_forms():
    """Over a duration T before the impact at v: every wheel locked, v + mu g T and a path of v T + mu g T^2 / 2;
    every wheel free, v + f g T with f the rolling resistance, and v T + f g T^2 / 2; the two phases in turn (free,
    then locked up to the impact) add up."""
    v, mu, f = 14.0, 0.7, 0.015
    rows = [(phases([1.0], [mu], [1.5]), impact(v)), (phases([0.0], [mu], [3.0], f=f), impact(v))]
    out = run(("duration",), rows)
    assert out.speed[0, 0] == pytest.approx(v + mu * G0 * 1.5, rel=1e-5)
    assert out.distance[0, 0] == pytest.approx(v * 1.5 + 0.5 * mu * G0 * 1.5 ** 2, rel=1e-5)
    assert out.time[0, 0] == pytest.approx(-1.5, abs=1e-12)
    assert out.speed[1, 0] == pytest.approx(v + f * G0 * 3.0, rel=1e-6)
    assert out.distance[1, 0] == pytest.approx(v * 3.0 + 0.5 * f * G0 * 3.0 ** 2, rel=1e-6)
    both = run(("duration", "duration"), [(phases([0.0, 1.0], [mu, mu], [3.0, 1.5], f=f), impact(v))])
    locked_start = v + mu * G0 * 1.5
    assert both.speed[0, 1] == pytest.approx(locked_start, rel=1e-5)
    assert both.speed[0, 0] == pytest.approx(locked_start + f * G0 * 3.0, rel=1e-5)
    np.testing.assert_allclose(both.time[0], [-4.5, -1.5], atol=1e-12)


@pytest.mark.slow
def test_the_motion_run_forward_from_the_approachs_start_returns_to_the_impact():
    """A turning, braked approach of two phases (free rolling for 1 s with the front wheels steered, then braked at
    half the friction over 12 m on another surface): the motion's own step (``motion._step``), run forward from the
    approach's start with the approach's steps, arrives at the impact state (to 0.1 mm, 0.1 mm/s, 1e-4 rad/s)."""
    p = phases([0.0, 0.5], [0.8, 0.6], [1.0, 12.0], steer=0.05)
    start = impact(14.0, 3.0, r=0.2, yaw=0.3, x=3.0, y=-2.0)
    out = run(("duration", "distance"), [(p, start)], path=True)
    times = out.path[0, :, 0]
    assert times[0] == pytest.approx(out.time[0, 0]) and times[-1] == 0.0 and np.all(np.diff(times) > 0)
    carry = M.start_carry(M.Planar(out.position[0, 0], np.radians(out.yaw[0, 0]), out.velocity[0, 0],
                                   out.yaw_rate[0, 0]))
    steps = np.diff(times)

    def phase(carry, k):
        wheels = jax.tree_util.tree_map(lambda x: x[k], p.wheels)
        b = M.body(MASS, IZZ, CG_HEIGHT, CHASSIS, wheels, p.friction[k], M.TIME_STEP)
        # the approach's first step reads the load transfer of the forces at its start
        carry = carry._replace(accel=M.step_function()(b, carry, steps[0]).accel) if k == 0 else carry
        return jax.lax.scan(lambda c, dt: (M.step_function()(b, c, dt), None), carry,
                            steps[k * PHASE_STEPS:(k + 1) * PHASE_STEPS])[0]

    end = reference_jit(lambda c: phase(phase(c, 0), 1))(carry).state
    np.testing.assert_allclose(end.position, start.position, atol=1e-4)
    turned = np.remainder(float(end.yaw) - float(start.yaw) + np.pi, 2 * np.pi) - np.pi  # the start's yaw is wrapped
    assert turned == pytest.approx(0.0, abs=1e-4)
    np.testing.assert_allclose(end.velocity, start.velocity, atol=1e-4)
    assert float(end.yaw_rate) == pytest.approx(float(start.yaw_rate), abs=1e-4)


@pytest.mark.slow
def test_a_vehicle_at_rest_at_the_impact_stays_at_rest_and_its_derivatives_are_finite():
    """Locked wheels before an impact at rest: the approach is at rest too (no friction force acts on a vehicle at
    rest), and its derivatives with respect to the impact speed are finite."""
    def speed(v):
        out = approach(MASS, IZZ, CG_HEIGHT, CHASSIS, phases([1.0], [0.7], [1.0]), ("duration",),
                       impact(0.0)._replace(velocity=jnp.stack([v, 0.0])))
        return out.speed[0], out.distance[0]

    (value, distance), (slope, _) = reference_jit(lambda v: jax.jvp(speed, (v,), (1.0,)))(0.0)
    assert float(value) == 0.0 and float(distance) == 0.0
    assert np.isfinite(float(slope))


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["forward", "reverse"])
def test_derivatives_of_the_approach_match_central_differences(mode):
    """d (the start's speed, time, x, y and yaw, and its path to the impact) / d (the impact speed, the yaw rate
    at the impact, the skid's friction and its distance) of a turning two-phase approach, in forward mode
    (``jax.jacfwd``) and reverse mode (``jax.jacrev``), against central differences of the same program's values."""
    p = phases([0.0, 1.0], [0.8, 0.7], [1.2, 15.0], steer=0.04)

    def outputs(x):
        v, r, mu, d = x[0], x[1], x[2], x[3]
        q = p._replace(friction=jnp.stack([0.8, mu]), length=jnp.stack([1.2, d]))
        s = M.Planar(jnp.array([1.0, 2.0]), jnp.asarray(0.2), jnp.stack([v * jnp.cos(0.2), v * jnp.sin(0.2)]), r)
        out = approach(MASS, IZZ, CG_HEIGHT, CHASSIS, q, ("duration", "distance"), s)
        return jnp.stack([out.speed[0], out.time[0], out.position[0, 0], out.position[0, 1], out.yaw[0],
                          out.distance[0], out.speed[1]])

    jac = jax.jacfwd if mode == "forward" else jax.jacrev
    program = reference_jit(lambda x: (outputs(x), jac(outputs)(x)))
    x = np.array([13.0, 0.15, 0.7, 15.0])
    _, derivative = program(x)
    h = np.array([1e-4, 1e-5, 1e-5, 1e-4])
    central = np.stack([(program(x + h[i] * np.eye(4)[i])[0] - program(x - h[i] * np.eye(4)[i])[0]) / (2 * h[i])
                        for i in range(4)], axis=1)
    assert np.all(np.isfinite(derivative))
    np.testing.assert_allclose(derivative, central, rtol=1e-4, atol=1e-5)


@pytest.mark.slow
def test_the_state_at_given_times_is_the_closed_form_and_reaches_back_beyond_the_first_phase():
    """Free rolling for 2 s, then a locked skid of 20 m to the impact at 12 m/s: the speed at the impact, within the
    skid (v + mu g t back from it), at the skid's start, and within and beyond the free phase (the free phase run
    further back: v_start + f g t), and the path back to each; a time after the impact is not the approach's (NaN)."""
    f, mu, v, d = 0.015, 0.7, 12.0, 20.0
    p = phases([0.0, 1.0], [mu, mu], [2.0, d], f=f)
    start = np.sqrt(v * v + 2 * mu * G0 * d)
    skid = (start - v) / (mu * G0)
    at = np.array([0.0, -0.5, -skid, -skid - 1.0, -skid - 3.5, 0.3])
    program = reference_jit(lambda p, s, a: approach(MASS, IZZ, CG_HEIGHT, CHASSIS, p, ("duration", "distance"), s,
                                                     at=a))
    out = jax.tree_util.tree_map(np.asarray, program(p, impact(v), at)).at
    speeds = [v, v + mu * G0 * 0.5, start, start + f * G0 * 1.0, start + f * G0 * 3.5]
    np.testing.assert_allclose(out.speed[:5], speeds, rtol=1e-6)
    paths = [0.0, v * 0.5 + 0.5 * mu * G0 * 0.25, d, d + start + 0.5 * f * G0,
             d + start * 3.5 + 0.5 * f * G0 * 3.5 ** 2]
    # within a step the state is interpolated linearly: a path quadratic in time is met to a dt^2 / 8, 0.1 mm
    np.testing.assert_allclose(out.distance[:5], paths, rtol=0, atol=1e-4)
    np.testing.assert_allclose(out.position[:5, 0], -np.array(paths), rtol=0, atol=1e-4)
    assert np.isnan(out.speed[5]) and np.isnan(out.position[5]).all()
