"""Contact interactions (``ks_jax.model.interaction``: the watched motion after the first exchange, and the KS
exchanges that follow) against independent references: the closed form of sequential 1-D impacts of three cars in
line; the conservation of linear and angular momentum on a frictionless road; kinetic energy that never grows on a
road with friction; the free motion's first contact with a pole (a closed form, and ``contact.first_contact``);
``motion_loop.to_rest`` of each vehicle alone where the bodies part after one exchange; central finite differences of
the forward-mode derivatives; and the exchange slots running out.

Every case is three cars and a pole on a flat road (a car or the pole not in a case parked far away), the first
exchange the automatic contact of cars 0 and 1 (``contact.automatic_exchange``): one program (``jax.jacfwd`` of the
whole case with respect to car 0's speed, its values the auxiliary output), compiled once with the quick settings
(``samples.reference_jit``) and run on every case at once, gives what every check reads; the references that
need JAX (``motion_loop.to_rest``, ``contact.first_contact``, the separations at the end) are small programs of their
own."""

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ks_jax.model import motion as M
from ks_jax.model import motion_loop as ML
from ks_jax.model.contact import advance, automatic_exchange, disc_gap, first_contact, separation
from ks_jax.model.interaction import APPROACH_TOLERANCE, Bodies, Interactions, Watch, interact
from ks_jax.model.pairs import pairs_of
from ks_jax.model.types import Contact, State, Vehicle
from samples import reference_jit

# every test reads the one program of the module's cases (``results``), which takes most of the file's time: slow
pytestmark = pytest.mark.slow

DT, LIMIT, SLOTS = M.TIME_STEP, 4.0, 8  # the step, the time limit (s) and the exchange slots of every case
STEPS = ML.steps_for(LIMIT, DT)
LENGTH, WIDTH, HEIGHT = 4.5, 1.8, 1.4  # m, every car; the CG in the middle of its box, at half its height
POLE = 0.3  # m, the pole's diameter
VEHICLES = 3  # three cars, then the pole (body 3)
PAIRS = pairs_of(VEHICLES, 1)
CHASSIS = M.Chassis(jnp.asarray(2.7), jnp.asarray(1.55), jnp.asarray(1.35))
PARKED, POLE_AWAY = (-300.0, 300.0), (300.0, -300.0)  # where a car or the pole not in a case stands


class Row(NamedTuple):
    """One case: per car (3,) mass kg, izz kg m^2, position (3, 2) m, yaw rad, speed m/s, course rad, yaw_rate
    rad/s; the pole's position (2,) m; the road's friction, every wheel's brake fraction; the exchanges'
    restitution and friction (the first exchange's and every later one's)."""

    mass: np.ndarray
    izz: np.ndarray
    position: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    course: np.ndarray
    yaw_rate: np.ndarray
    pole: np.ndarray
    road: np.ndarray
    brake: np.ndarray
    restitution: np.ndarray
    friction: np.ndarray


def row(cars, pole=POLE_AWAY, road=0.0, brake=0.0, restitution=0.3, friction=0.5):
    """A ``Row`` of ``cars``, each (mass, izz, x, y, yaw, speed, course, yaw_rate); a third car not given is parked
    far away."""
    cars = list(cars) + [(1500.0, 2500.0, *PARKED, 0.0, 0.0, 0.0, 0.0)] * (VEHICLES - len(cars))
    c = np.asarray(cars, float)
    return Row(c[:, 0], c[:, 1], c[:, 2:4], c[:, 4], c[:, 5], c[:, 6], c[:, 7], np.asarray(pole, float),
               *(np.asarray(x, float) for x in (road, brake, restitution, friction)))


def car_vehicle(mass, izz):
    """A car of the test's box, its CG in the middle (Izz ``izz``; Ixx, Iyy in proportion)."""
    return Vehicle(mass, jnp.diag(jnp.stack([0.2 * izz, 0.9 * izz, izz])), jnp.asarray(LENGTH), jnp.asarray(WIDTH),
                   jnp.asarray(HEIGHT), jnp.asarray(LENGTH / 2), jnp.asarray(HEIGHT / 2))


def pole_vehicle():
    """The pole as a body: an infinite-mass box about the disc, from the ground up."""
    return Vehicle(jnp.asarray(jnp.inf), jnp.eye(3), jnp.asarray(POLE), jnp.asarray(POLE), jnp.asarray(10.0),
                   jnp.asarray(POLE / 2), jnp.asarray(0.0))


def initial_states(r: Row, speed0):
    """The cars' ``State`` at the case start (t = 0), car 0's speed ``speed0``."""
    speed = jnp.asarray(r.speed).at[0].set(speed0)
    zero = jnp.zeros_like(r.yaw[0])
    return [State(jnp.stack([r.position[k, 0], r.position[k, 1], jnp.asarray(HEIGHT / 2)]),
                  jnp.stack([speed[k] * jnp.cos(r.course[k]), speed[k] * jnp.sin(r.course[k]), zero]), r.yaw[k], zero,
                  zero, jnp.stack([zero, zero, r.yaw_rate[k]])) for k in range(VEHICLES)]


class Case(NamedTuple):
    """What a case's program gives besides the derivatives: the outputs differentiated (``outputs``), the first
    exchange's instant from the case start ``t0`` s, the vehicles' ``start`` (``motion.Planar`` at t0, velocities
    after the first exchange) and the ``Interactions``."""

    outputs: jnp.ndarray
    t0: jnp.ndarray
    start: M.Planar
    out: Interactions


def motion_bodies(r: Row):
    """The cars' ``motion.Body`` (V, ...): free or braked wheels as the row says, no rolling resistance."""
    wheels = M.Wheels(jnp.full(4, r.brake), jnp.zeros(()), jnp.zeros(()))
    return jax.vmap(lambda m, izz: M.body(m, izz, HEIGHT / 2, CHASSIS, wheels, r.road, DT))(r.mass, r.izz)


def run_case(speed0, r: Row):
    """The case ``r`` with car 0's speed ``speed0``: the first exchange (cars 0 and 1, automatic contact, no
    penetration time), the cars moved freely to its instant, and the watched motion from there: (the outputs
    differentiated, (5,): both cars' rest positions and the second exchange's impulse; the whole ``Case``)."""
    cars = [car_vehicle(r.mass[k], r.izz[k]) for k in range(VEHICLES)]
    states = initial_states(r, speed0)
    contact = Contact(jnp.zeros(3), jnp.array([1.0, 0.0, 0.0]), r.restitution, r.friction, jnp.zeros(()))
    first = automatic_exchange(cars[0], states[0], cars[1], states[1], contact, 0.0, auto_point=True,
                               auto_normal=True)
    t0 = first.contact.time
    moved = [advance(s, t0) for s in states]
    velocity = [first.vehicles[0].velocity_after, first.vehicles[1].velocity_after, moved[2].velocity]
    yaw_rate = [first.vehicles[0].yaw_rate_after, first.vehicles[1].yaw_rate_after, moved[2].angular_velocity[2]]
    start = M.Planar(jnp.stack([s.position[:2] for s in moved]), jnp.stack([s.yaw for s in moved]),
                     jnp.stack([v[:2] for v in velocity]), jnp.stack(yaw_rate))
    vehicles = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *cars, pole_vehicle())
    fixed = M.Planar(r.pole[None], jnp.zeros(1), jnp.zeros((1, 2)), jnp.zeros(1))
    bodies = Bodies(vehicles, jnp.array([HEIGHT / 2] * VEHICLES + [0.0]), motion_bodies(r), fixed)
    every = jnp.ones(len(PAIRS))
    watch = Watch(r.restitution * every, r.friction * every, 0.0 * every, jnp.asarray(APPROACH_TOLERANCE))
    out = interact(bodies, start, first, (0, 1), watch, max_exchanges=SLOTS, dt=DT, time_limit=LIMIT,
                   poles=(VEHICLES,), path=True)
    outputs = jnp.concatenate([out.rest[0].rest_position, out.rest[1].rest_position,
                               out.exchanges.contact.impulse_magnitude[1:2]])
    return outputs, Case(outputs, t0, start, out)


@functools.cache
def _program():
    return reference_jit(jax.vmap(jax.jacfwd(run_case, has_aux=True)))


def run(rows, speeds=None):
    """Every row at once: (d outputs / d speed0 (n, 5), ``Case`` of (n, ...) leaves), as NumPy arrays."""
    batch = jax.tree_util.tree_map(lambda *x: np.stack(x), *rows)
    speeds = batch.speed[:, 0] if speeds is None else np.asarray(speeds, float)
    return jax.tree_util.tree_map(np.asarray, _program()(speeds, batch))


# three cars in line on a frictionless road (free wheels, no rolling resistance): masses kg, speeds m/s, x m,
# restitution. The second has hits 4 ms after another (the touch inside the step after an exchange's); the last
# needs 10 exchanges, two more than the slots
CHAINS = [([1500.0, 1400.0, 1600.0], [20.0, 0.0, 0.0], [-10.0, 0.0, 6.0], 0.3),
          ([1600.0, 500.0, 1600.0], [12.0, 0.0, 0.0], [-6.5, 0.0, 4.6], 0.5),
          ([1200.0, 1800.0, 1000.0], [25.0, 3.0, 1.0], [-12.0, 0.0, 7.0], 0.1),
          ([1800.0, 200.0, 1800.0], [10.0, 0.0, 0.0], [-5.5, 0.0, 5.5], 0.5)]


def chain_row(masses, speeds, xs, e):
    """Cars in line along +x (yaw 0, on y = 0) at ``xs`` with ``speeds``, restitution ``e``."""
    return row([(m, 1.8 * m, x, 0.0, 0.0, v, 0.0, 0.0) for m, v, x in zip(masses, speeds, xs)], restitution=e,
               friction=0.5)


def oblique_row(yaw, y, road, brake, speed=15.0, restitution=0.1):
    """Car 0 (1500 kg) at ``speed`` along +x from (-5, 0) into car 1 (1300 kg) at rest at (0, ``y``), turned
    ``yaw``: an oblique impact whose rotations bring the cars together again (a side-slap), or part them."""
    return row([(1500.0, 2700.0, -5.0, 0.0, 0.0, speed, 0.0, 0.0), (1300.0, 2200.0, 0.0, y, yaw, 0.0, 0.0, 0.0)],
               road=road, brake=brake, restitution=restitution)


SPEED_STEP = 1e-5  # m/s, the finite differences' step in car 0's speed
MOMENTUM = [oblique_row(math.pi / 2, 1.5, 0.0, 0.0), oblique_row(1.2, 2.0, 0.0, 0.0)]
DERIVATIVE = [oblique_row(1.2, 1.0, 0.7, 1.0), oblique_row(math.pi / 2, 1.5, 0.7, 1.0)]
ENERGY = DERIVATIVE + [oblique_row(math.pi / 2, 1.0, 0.7, 0.3)]
SEPARATING = [oblique_row(1.2, 2.0, 0.7, 1.0), oblique_row(0.8, 1.5, 0.7, 1.0, restitution=0.3),
              oblique_row(2.0, 2.0, 0.8, 1.0, speed=12.0)]
# car 0 (750 kg) squarely into car 1 (1500 kg) with restitution 1/2: car 0 stops, car 1 slides on at half the speed,
# without turning, into the pole 3 m ahead; and an oblique hit that sends car 1 spinning into the pole
SLIDE_GAP = 3.0
POLES = [row([(750.0, 1300.0, -5.5, 0.0, 0.0, 10.0, 0.0, 0.0), (1500.0, 2500.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)],
             pole=(LENGTH / 2 + SLIDE_GAP + POLE / 2, 0.0), restitution=0.5),
         row([(1500.0, 2500.0, -6.0, 1.5, -0.25, 15.0, -0.25, 0.0), (1300.0, 2200.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)],
             pole=(6.0, -2.0), restitution=0.2)]


def _keys():
    """Every row of the one batch, named (kind, index[, -1 | 0 | 1: car 0's speed less ``SPEED_STEP``, as given, or
    more]), with the row and car 0's speed (None: the row's)."""
    named = [(("chain", k), chain_row(*c), None) for k, c in enumerate(CHAINS)]
    named += [(("momentum", k), r, None) for k, r in enumerate(MOMENTUM)]
    named += [(("derivative", k, s), r, float(r.speed[0]) + s * SPEED_STEP) for k, r in enumerate(DERIVATIVE)
              for s in (-1, 0, 1)]
    named += [(("energy", k), r, None) for k, r in enumerate(ENERGY) if k >= len(DERIVATIVE)]
    named += [(("separating", k), r, None) for k, r in enumerate(SEPARATING)]
    named += [(("pole", k), r, None) for k, r in enumerate(POLES)]
    return named


class Results:
    """The batch's derivatives and cases, read by a row's name (``_keys``)."""

    def __init__(self):
        named = _keys()
        self.index = {key: n for n, (key, _, _) in enumerate(named)}
        self.rows = {key: r for key, r, _ in named}
        speeds = [float(r.speed[0]) if s is None else s for _, r, s in named]
        self.derivative, self.case = run([r for _, r, _ in named], speeds)

    def __call__(self, *key):
        """(d outputs / d speed0, ``Case``, ``Row``) of one row; an energy row that is a derivative's centre is
        that row."""
        if key[0] == "energy" and key[1] < len(DERIVATIVE):
            key = ("derivative", key[1], 0)
        n = self.index[key]
        return self.derivative[n], jax.tree_util.tree_map(lambda x: x[n], self.case), self.rows[key]


@pytest.fixture(scope="module")
def results():
    return Results()


def sequential_impacts(masses, speeds, xs, e, end):
    """The closed form of cars in line (each ``LENGTH`` long) meeting one pair of neighbours at a time: at the
    first touch of a closing pair k, k + 1 the impulse J = (1 + e) m_k m_k+1 / (m_k + m_k+1) (v_k - v_k+1) changes
    their velocities by -J / m_k and J / m_k+1; between impacts every car keeps its velocity. Returns the impacts up
    to ``end`` s, [(t s, (k, k + 1), J N s, velocities after (3,))], and the positions and velocities at ``end``."""
    m, v, x = (np.array(a, float) for a in (masses, speeds, xs))
    t, impacts = 0.0, []
    while len(impacts) < 100:
        closing = [((x[k + 1] - x[k] - LENGTH) / (v[k] - v[k + 1]), k) for k in range(len(m) - 1) if v[k] > v[k + 1]]
        if not closing or t + min(closing)[0] > end:
            break
        step, k = min(closing)
        t, x = t + step, x + v * step
        j = (1 + e) * m[k] * m[k + 1] / (m[k] + m[k + 1]) * (v[k] - v[k + 1])
        v[k], v[k + 1] = v[k] - j / m[k], v[k + 1] + j / m[k + 1]
        impacts.append((t, (k, k + 1), j, v.copy()))
    return impacts, x + v * (end - t), v


def step_velocities(case):
    """(V, STEPS, 3): each car's mean velocity (vx, vy, yaw rate) over every step, from its path."""
    path = np.stack([r.path for r in case.out.rest])
    return np.diff(path[:, :, 1:4], axis=1) / DT


def clean_steps(case):
    """(STEPS,) bool: the steps without an exchange inside them (one at a step's end changes the velocities from
    there on, so that the step's mean velocity is that before it)."""
    clean = np.ones(STEPS, bool)
    for t in case.out.time[:case.out.count]:
        n = t / DT
        if abs(n - round(n)) > 1e-6:
            clean[int(n)] = False
    return clean


def after_exchange(case, k):
    """The step from which the velocities after exchange ``k`` hold (its first step wholly after it)."""
    return math.ceil(case.out.time[k] / DT - 1e-6)


def test_three_cars_in_line_meet_the_closed_form_of_sequential_impacts(results):
    """Three cars in line on a frictionless road (free wheels, no rolling resistance, no penetration time): every
    exchange (its time, within 1e-9 s: the touch interpolated within its step is exact for cars that translate; its
    impulse, pair and interaction), each car's velocity and position at the time limit, the cumulative delta-V of
    each car's first interaction and the energy lost, against the closed form of sequential 1-D impacts. The first
    case's third exchange is the first car catching the second again, a new interaction of that pair; in the second,
    a pair touches 4 ms after another pair's exchange, in the step after it."""
    for k, (masses, speeds, xs, e) in enumerate(CHAINS[:-1]):
        _, case, _ = results("chain", k)
        out = case.out
        t0 = float(case.t0)
        impacts, x, v = sequential_impacts(masses, speeds, xs, e, t0 + STEPS * DT)
        assert impacts[0][1] == (0, 1)
        np.testing.assert_allclose(t0, impacts[0][0], rtol=0, atol=1e-12)
        assert int(out.count) == len(impacts) and not bool(out.exhausted) and not out.overlapping.any()
        np.testing.assert_allclose(out.time[:len(impacts)], [t - t0 for t, *_ in impacts], rtol=0, atol=1e-9)
        assert out.between[:len(impacts)].tolist() == [list(pair) for _, pair, _, _ in impacts]
        assert out.interaction[:len(impacts)].tolist() == list(range(len(impacts)))
        np.testing.assert_allclose(out.exchanges.contact.impulse_magnitude[:len(impacts)],
                                   [j for _, _, j, _ in impacts], rtol=1e-9)
        if k == 0:
            assert [pair for _, pair, _, _ in impacts] == [(0, 1), (1, 2), (0, 1)]
        rest = np.stack([r.rest_position for r in out.rest])
        np.testing.assert_allclose(rest, np.stack([x, np.zeros(3)], -1), rtol=0, atol=1e-8)
        np.testing.assert_allclose(step_velocities(case)[:, -1], np.stack([v, np.zeros(3), np.zeros(3)], -1),
                                   rtol=0, atol=1e-8)
        # each car's first interaction is its first impact (a touch at an instant), its speed before it the initial
        before = np.asarray(speeds, float)
        for car in range(VEHICLES):
            first = next(n for n, (_, pair, _, _) in enumerate(impacts) if car in pair)
            assert int(out.first_interaction[car]) == first
            np.testing.assert_allclose(out.delta_v_cumulative[car], [impacts[first][3][car] - before[car], 0.0, 0.0],
                                       rtol=0, atol=1e-9)
        energy = 0.5 * np.dot(masses, before ** 2) - 0.5 * np.dot(masses, impacts[-1][3] ** 2)
        np.testing.assert_allclose(float(out.energy_loss_total), energy, rtol=1e-9)


def cross(a, b):
    """The z component of planar vectors' cross products (..., 2) x (..., 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def initial_momenta(r: Row):
    """The cars' total linear momentum (2,) N s and angular momentum about the origin (z) kg m^2/s at the case
    start, which free motion keeps until the first exchange."""
    v = r.speed[:, None] * np.stack([np.cos(r.course), np.sin(r.course)], -1)
    return r.mass @ v, np.sum(r.mass * cross(r.position, v) + r.izz * r.yaw_rate)


def test_momentum_is_kept_by_every_exchange_of_an_oblique_impact_and_its_side_slap(results):
    """Road friction 0: the cars' total linear momentum and angular momentum about a fixed point (z, with each
    car's Izz times its yaw rate) after every exchange, read from the paths (positions, and velocities as the
    steps' differences), are those before the first. Both cases are oblique impacts whose rotations bring the cars
    together again: in the first while they still overlap (three exchanges of the first interaction, at the steps'
    instants) and once more later; in the second after they parted, within a step. The first case's cumulative
    delta-V is, by its definition, the velocity after the first interaction's last exchange minus that before its
    first; with no tyre forces, also the sum of its impulses over the mass."""
    for k, r in enumerate(MOMENTUM):
        _, case, _ = results("momentum", k)
        out = case.out
        count = int(out.count)
        assert count >= 2 and not bool(out.exhausted)
        assert (out.between[:count] == [0, 1]).all() and np.all(np.abs(case.start.yaw_rate[:2]) > 0.1)
        p0, l0 = initial_momenta(r)
        scale = r.mass @ r.speed  # N s
        path = np.stack([c.path for c in out.rest])
        velocity = step_velocities(case)
        for e in range(count):
            n = after_exchange(case, e)
            assert e + 1 == count or out.time[e + 1] >= (n + 1) * DT - 1e-9
            v = velocity[:, n]
            p = r.mass @ v[:, :2]
            angular = np.sum(r.mass * cross(path[:, n, 1:3], v[:, :2]) + r.izz * v[:, 2])
            np.testing.assert_allclose(p, p0, rtol=0, atol=1e-10 * scale)
            np.testing.assert_allclose(angular, l0, rtol=0, atol=1e-10 * scale * 10.0)
        if k == 0:
            last = max(e for e in range(count) if out.interaction[e] == 0)
            assert last >= 1  # the first interaction has more than one exchange
            v = velocity[:, after_exchange(case, last)]
            initial = r.speed[:, None] * np.stack([np.cos(r.course), np.sin(r.course)], -1)
            for car in (0, 1):
                assert int(out.first_interaction[car]) == 0
                np.testing.assert_allclose(out.delta_v_cumulative[car, :2], v[car, :2] - initial[car], atol=1e-9)
                np.testing.assert_allclose(out.delta_v_impulses[car], out.delta_v_cumulative[car], atol=1e-9)


def test_kinetic_energy_never_grows_along_the_path_across_exchanges(results):
    """Road friction > 0 (locked wheels, and wheels braked by 0.3 with their lateral grip): the cars' kinetic energy
    (translational and yaw) of every step's mean velocities never grows along the path, from the first exchange to
    rest, across the later exchanges (the steps with an exchange inside them left out: their mean mixes the
    velocities before and after it)."""
    for k in range(len(ENERGY)):
        _, case, r = results("energy", k)
        assert int(case.out.count) >= 3 and all(bool(c.at_rest) for c in case.out.rest)
        v = step_velocities(case)[:, clean_steps(case)]
        energy = 0.5 * np.sum(r.mass[:, None] * np.sum(v[:, :, :2] ** 2, -1) + r.izz[:, None] * v[:, :, 2] ** 2, 0)
        assert energy[0] > 1e5 and energy[-1] == 0.0
        assert np.all(np.diff(energy) <= 1e-12 * energy[0]), np.max(np.diff(energy))


@functools.cache
def _first_contact():
    def touch(position, yaw, velocity, yaw_rate, pole):
        zero = jnp.zeros_like(yaw)
        car = State(jnp.stack([position[0], position[1], HEIGHT / 2]), jnp.stack([velocity[0], velocity[1], zero]),
                    yaw, zero, zero, jnp.stack([zero, zero, yaw_rate]))
        fixed = State(jnp.stack([pole[0], pole[1], zero]), jnp.zeros(3), zero, zero, zero, jnp.zeros(3))
        return first_contact(car_vehicle(jnp.asarray(1300.0), jnp.asarray(2200.0)), car, pole_vehicle(), fixed,
                             gap=disc_gap)

    return reference_jit(touch)


def _at_exchange(case, k, car, side):
    """Car ``car``'s position (2,) and yaw at exchange ``k`` (in which it is body ``side``), from its path: the
    state at the end of the exchange's step taken back along the velocities after it."""
    n = after_exchange(case, k)
    vehicle = jax.tree_util.tree_map(lambda x: x[k], case.out.exchanges.vehicles[side])
    back = n * DT - case.out.time[k]
    path = case.out.rest[car].path[n]
    return path[1:3] - back * vehicle.velocity_after[:2], path[3] - back * vehicle.yaw_rate_after


def test_a_car_sliding_or_spinning_into_a_pole_meets_it_when_and_where_its_free_path_says(results):
    """A frictionless road: car 1, sent sliding straight (no yaw rate) by a square hit, meets a pole 3 m ahead
    when, where and with the impulse a translating box against a fixed disc gives in closed form (t = gap / v,
    J = (1 + e) m v); sent spinning by an oblique hit, it meets the pole when and where
    ``contact.first_contact`` (the disc's gap, ``contact.disc_gap``) finds on the free motion from the state after
    the first exchange: within 1e-5 s, the touch interpolated linearly within its step while the spinning car's
    gap is curved."""
    _, slide, r = results("pole", 0)
    out = slide.out
    assert out.between[1].tolist() == [1, VEHICLES]  # nothing else first
    speed = (1 + r.restitution) * r.mass[0] * r.speed[0] / (r.mass[0] + r.mass[1])  # car 0 stops
    np.testing.assert_allclose(slide.start.velocity[:2], [[0.0, 0.0], [speed, 0.0]], atol=1e-12)
    np.testing.assert_allclose(slide.t0, (r.position[1, 0] - r.position[0, 0] - LENGTH) / r.speed[0], atol=1e-12)
    np.testing.assert_allclose(out.time[1], SLIDE_GAP / speed, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out.exchanges.contact.impulse_magnitude[1], (1 + r.restitution) * r.mass[1] * speed,
                               rtol=1e-9)
    position, yaw = _at_exchange(slide, 1, 1, 0)
    np.testing.assert_allclose(position, [r.position[1, 0] + SLIDE_GAP, 0.0], atol=1e-9)
    assert abs(yaw) < 1e-12

    _, spin, r = results("pole", 1)
    out, s = spin.out, spin.start
    assert out.between[1].tolist() == [1, VEHICLES] and abs(s.yaw_rate[1]) > 1.0
    t, found = _first_contact()(s.position[1], s.yaw[1], s.velocity[1], s.yaw_rate[1], r.pole)
    assert bool(found)
    np.testing.assert_allclose(out.time[1], float(t), rtol=0, atol=1e-5)
    position, yaw = _at_exchange(spin, 1, 1, 0)
    speed = np.linalg.norm(s.velocity[1])
    np.testing.assert_allclose(position, s.position[1] + float(t) * s.velocity[1], rtol=0, atol=speed * 1e-5)
    np.testing.assert_allclose(yaw, s.yaw[1] + float(t) * s.yaw_rate[1], rtol=0, atol=abs(s.yaw_rate[1]) * 1e-5)


@functools.cache
def _to_rest():
    def one(mass, izz, road, brake, start):
        wheels = M.Wheels(jnp.full(4, brake), jnp.zeros(()), jnp.zeros(()))
        return ML.to_rest(mass, izz, HEIGHT / 2, CHASSIS, wheels, road, start, dt=DT, time_limit=LIMIT)

    return reference_jit(jax.vmap(one))


def test_an_exchange_that_parts_the_cars_for_good_leaves_each_to_move_to_rest_alone(results):
    """One exchange after which the cars part and never meet again (count 1): each car's rest position, rest yaw,
    time and distance to rest are those of ``motion_loop.to_rest`` of that car alone from the same start, to 1e-12
    (the parked third car's too)."""
    cases = [results("separating", k) for k in range(len(SEPARATING))]
    for _, case, _ in cases:
        assert int(case.out.count) == 1 and not bool(case.out.exhausted) and not case.out.overlapping.any()
    flat = lambda get: np.concatenate([get(case, r) for _, case, r in cases])  # noqa: E731
    starts = M.Planar(*(flat(lambda c, r, f=f: getattr(c.start, f)) for f in M.Planar._fields))
    alone = _to_rest()(flat(lambda c, r: r.mass), flat(lambda c, r: r.izz),
                       flat(lambda c, r: np.full(VEHICLES, r.road)), flat(lambda c, r: np.full(VEHICLES, r.brake)),
                       starts)
    for name in ("rest_position", "rest_yaw", "time_to_rest", "distance_to_rest", "at_rest"):
        engine = flat(lambda c, r: np.stack([getattr(x, name) for x in c.out.rest]))
        np.testing.assert_allclose(engine, np.asarray(getattr(alone, name)), rtol=1e-12, atol=0, err_msg=name)


def test_forward_mode_derivatives_match_central_differences_where_the_exchanges_do_not_change(results):
    """``jax.jacfwd`` with respect to car 0's initial speed of both cars' rest positions and of the second
    exchange's impulse (a side-slap within a step, and the second exchange of a T-bone's first interaction, on a
    road with friction) against central differences of +-1e-5 m/s, at which the exchanges (pairs, interactions,
    count) are the same."""
    for k in range(len(DERIVATIVE)):
        (low, centre, high) = (results("derivative", k, s) for s in (-1, 0, 1))
        for _, case, _ in (low, high):
            count = int(centre[1].out.count)
            assert int(case.out.count) == count >= 2
            assert (case.out.between[:count] == centre[1].out.between[:count]).all()
            assert (case.out.interaction[:count] == centre[1].out.interaction[:count]).all()
        differences = (high[1].outputs - low[1].outputs) / (2 * SPEED_STEP)
        assert np.all(np.abs(centre[0]) > 1e-3)
        np.testing.assert_allclose(centre[0], differences, rtol=1e-6, atol=1e-9)


@functools.cache
def _gaps():
    def gaps(position, yaw, pole):
        states = [State(jnp.stack([position[k, 0], position[k, 1], HEIGHT / 2]), jnp.zeros(3), yaw[k], 0.0 * yaw[k],
                        0.0 * yaw[k], jnp.zeros(3)) for k in range(VEHICLES)]
        states.append(State(jnp.stack([pole[0], pole[1], 0.0]), jnp.zeros(3), 0.0 * yaw[0], 0.0 * yaw[0],
                            0.0 * yaw[0], jnp.zeros(3)))
        car = car_vehicle(jnp.asarray(1500.0), jnp.asarray(2500.0))
        return jnp.stack([(disc_gap if j == VEHICLES else separation)(car, states[i], pole_vehicle() if j == VEHICLES
                                                                       else car, states[j], 0.0) for i, j in PAIRS])

    return reference_jit(jax.vmap(gaps))


def test_too_few_slots_set_exhausted_and_a_pair_left_overlapping_is_reported(results):
    """A light car between two heavy ones on a frictionless road needs 10 exchanges (the closed form) and has 8
    slots: the 8 are the closed form's first 8, ``exhausted`` is set, and the pair due for the ninth is left
    overlapping. Every case's ``overlapping`` is what the footprints' separations (``contact.separation``, a pole's
    ``contact.disc_gap``) at the end say; no other case is exhausted."""
    masses, speeds, xs, e = CHAINS[-1]
    _, case, _ = results("chain", len(CHAINS) - 1)
    out = case.out
    impacts, _, _ = sequential_impacts(masses, speeds, xs, e, 100.0)
    assert len(impacts) == 10
    assert bool(out.exhausted) and int(out.count) == SLOTS
    np.testing.assert_allclose(out.time, [t - impacts[0][0] for t, *_ in impacts[:SLOTS]], rtol=0, atol=1e-9)
    assert out.between.tolist() == [list(pair) for _, pair, _, _ in impacts[:SLOTS]]
    np.testing.assert_allclose(out.exchanges.contact.impulse_magnitude, [j for _, _, j, _ in impacts[:SLOTS]],
                               rtol=1e-9)
    assert out.overlapping.tolist() == [pair == impacts[SLOTS][1] for pair in PAIRS]

    every = results.case.out
    position = np.stack([r.rest_position for r in every.rest], 1)
    yaw = np.radians(np.stack([r.rest_yaw for r in every.rest], 1))
    gaps = np.asarray(_gaps()(position, yaw, np.stack([r.pole for r in results.rows.values()])))
    assert np.min(np.abs(gaps)) > 1e-6
    np.testing.assert_array_equal(every.overlapping, gaps < 0)
    exhausted = np.zeros(len(results.index), bool)
    exhausted[results.index["chain", len(CHAINS) - 1]] = True
    np.testing.assert_array_equal(every.exhausted, exhausted)
