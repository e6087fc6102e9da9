"""Post-impact motion to rest: one vehicle on a flat road, planar, four wheels (docs/model.md, "Motion to rest").

State: the CG's position (x, y), yaw, the CG's velocity (vx, vy) and yaw rate, global. Each wheel
carries a vertical load (the static split by axle, plus longitudinal and lateral load transfer from the
CG's height and the vehicle's acceleration) and a tyre force inside its friction circle:

- ``free`` (brake fraction 0): rolling resistance f Fz against the wheel's rolling direction, and a
  lateral force from the slip angle alpha, mu' Fz tanh(k alpha / mu') (k = ``CORNERING``, mu' the
  friction left by rolling resistance): linear at small slip, saturating at the friction circle;
- ``locked`` (brake fraction 1): mu Fz against the wheel's velocity over the road;
- braked by a fraction b: (1 - b) of the free force plus b of the locked one, inside the circle
  because both are.

Integration: a fixed step ``dt`` (``lax.scan``; ``TIME_STEP`` by default). Velocities take the step's
change from the forces at the start of the step; positions and yaw the trapezoid of the velocities.
Two rules make rest exact and smooth:

- A step never adds kinetic energy: where the forces would overshoot rest (a friction force larger than
  what stops the wheel within the step), the velocity change is scaled back to the least kinetic energy
  along it. A straight skid or a spin in place then stops exactly, in the step where it stops.
- A step counts only the fraction phi of it during which the vehicle still moves: the time to
  dissipate the kinetic energy E at the forces' power P is 2 E / P for a constant deceleration, so
  phi = min(1, 2 E / (P dt)). Time, yaw and position advance by phi of the step, and the vehicle is at
  rest after the first step with phi < 1. A skid at constant deceleration is then exact, however long
  the step.

Near zero speed each friction direction is regularized: v / sqrt(|v|^2 + a^2), a a fraction of the speed
that the force changes in one step (``REGULARIZATION``), so that forces, rest positions and their
gradients are smooth and finite. The tyre's slip angle is regularized over the speed at which its
lateral stiffness would overshoot in one step (k g dt), which makes the explicit step stable.

Everything here is pure and unbatched: jit, vmap and differentiate at the edge.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..units import G0
from . import linalg as la

TIME_STEP = 0.005  # s, the default step
TIME_LIMIT = 20.0  # s, the default time limit
CORNERING = 15.0  # 1/rad: a tyre's cornering stiffness over its load (lateral force per load per radian of slip)
MAX_FRICTION = 10.0  # the road's friction at most (a racing tyre on a dry track reaches about 2)
REGULARIZATION = 0.3  # the friction direction's regularizing speed, as a fraction of one step's speed change


class Chassis(NamedTuple):
    """Where the wheels are: ``wheelbase`` () m; ``track`` () m; ``cg_to_front_axle`` () m, from the CG
    forwards to the front axle. The wheels are at body (a, +-t/2) and (a - wheelbase, +-t/2)."""

    wheelbase: jnp.ndarray
    track: jnp.ndarray
    cg_to_front_axle: jnp.ndarray


class Wheels(NamedTuple):
    """How the wheels run after the impact: ``brake`` (4,) in [0, 1] per wheel (front left, front right,
    rear left, rear right; 0 free, 1 locked); ``steer`` () rad, the front wheels' angle (left +);
    ``rolling_resistance`` () f."""

    brake: jnp.ndarray
    steer: jnp.ndarray
    rolling_resistance: jnp.ndarray


class Planar(NamedTuple):
    """A vehicle's planar state, global: ``position`` (2,) m of the CG; ``yaw`` () rad; ``velocity`` (2,) m/s
    of the CG; ``yaw_rate`` () rad/s."""

    position: jnp.ndarray
    yaw: jnp.ndarray
    velocity: jnp.ndarray
    yaw_rate: jnp.ndarray


class RestResult(NamedTuple):
    """A vehicle's motion from the exchange to rest (docs/model.md, "Results").

    rest_position (2,) m, the CG at rest; rest_yaw () deg in [0, 360); rotation_to_rest () deg, the yaw
    turned from the exchange to rest (signed, left +, not wrapped: 540 is one and a half turns);
    time_to_rest () s; distance_to_rest () m, the length of the CG's path; at_rest () bool, False where the
    vehicle still moves at the time limit (its "rest" is where it is then); path: None, or where asked for
    (``to_rest(path=True)``) the state at the start and after every step, (steps + 1, 4): time s, x m, y m,
    yaw rad."""

    rest_position: jnp.ndarray
    rest_yaw: jnp.ndarray
    rotation_to_rest: jnp.ndarray
    time_to_rest: jnp.ndarray
    distance_to_rest: jnp.ndarray
    at_rest: jnp.ndarray
    path: jnp.ndarray | None = None


class _Carry(NamedTuple):
    state: Planar
    accel: jnp.ndarray  # (2,) the CG's acceleration in the body frame at the last step (load transfer)
    time: jnp.ndarray
    distance: jnp.ndarray
    moving: jnp.ndarray  # the last step's fraction phi


def wheel_positions(chassis: Chassis):
    """(4, 2) body positions of the wheels: front left, front right, rear left, rear right."""
    a, L, t = chassis.cg_to_front_axle, chassis.wheelbase, chassis.track
    x = jnp.stack([a, a, a - L, a - L])
    y = 0.5 * jnp.stack([t, -t, t, -t])
    return jnp.stack([x, y], axis=-1)


class Body(NamedTuple):
    """What does not change during one vehicle's motion, computed once before the steps (``body``): the mass and
    yaw inertia; the wheels' body positions ``x``, ``y`` (4,) and their steer's cosine and sine (4,); the static
    loads (4,) and the loads each unit of longitudinal and lateral acceleration moves (4,); the weight; the
    wheels' brake fractions (4,), rolling resistance, the road's friction and the lateral grip left by rolling
    resistance; and the squares of the regularizing speeds (the module's docstring)."""

    mass: jnp.ndarray
    izz: jnp.ndarray
    x: jnp.ndarray
    y: jnp.ndarray
    cos_steer: jnp.ndarray
    sin_steer: jnp.ndarray
    static: jnp.ndarray
    pitch: jnp.ndarray
    lateral: jnp.ndarray
    weight: jnp.ndarray
    brake: jnp.ndarray
    rolling: jnp.ndarray
    friction: jnp.ndarray
    grip: jnp.ndarray
    locked_speed2: jnp.ndarray
    rolling_speed2: jnp.ndarray
    slip_speed2: jnp.ndarray


def body(mass, izz, cg_height, chassis: Chassis, wheels: Wheels, friction, dt) -> Body:
    """A vehicle's ``Body`` for steps of ``dt``."""
    a, L, t = chassis.cg_to_front_axle, chassis.wheelbase, chassis.track
    p = wheel_positions(chassis)
    ss, cs = la.sincos(wheels.steer)
    one, zero = jnp.ones_like(cs), jnp.zeros_like(ss)
    weight = mass * G0
    front, rear = (L - a) / L, a / L
    static = 0.5 * weight * jnp.stack([front, front, rear, rear])
    # acceleration moves m a h / L from the front axle to the rear; lateral acceleration to the left moves
    # m a h / t to the right (y < 0) wheels, shared by the axles as their static loads are
    pitch = 0.5 * mass * cg_height / L * jnp.stack([-one, -one, one, one])
    lateral = mass * cg_height / t * jnp.stack([-front, front, -rear, rear])
    f = wheels.rolling_resistance
    grip = la.safe_sqrt(jnp.maximum(friction * friction - f * f, 0.0))
    step = G0 * dt
    return Body(mass, izz, p[:, 0], p[:, 1], jnp.stack([cs, cs, one, one]), jnp.stack([ss, ss, zero, zero]),
                static, pitch, lateral, weight, jnp.clip(wheels.brake, 0.0, 1.0), f, friction, grip,
                (REGULARIZATION * friction * step) ** 2, (REGULARIZATION * f * step) ** 2, (CORNERING * step) ** 2)


def _loads(b: Body, ax, ay):
    """(4,) vertical loads at the body frame acceleration (ax, ay): a load that transfer would make negative (a
    lifted wheel) is 0, and the others are scaled so that the four carry m g."""
    loads = jnp.maximum(b.static + b.pitch * ax + b.lateral * ay, 0.0)
    return loads * b.weight / jnp.sum(loads)


def wheel_loads(mass, cg_height, chassis: Chassis, accel):
    """(4,) vertical loads, N: the static split by axle, halved per side, plus the load transfer of the body
    frame acceleration ``accel`` (2,) (longitudinal, lateral left +) at ``cg_height``. A load that transfer
    would make negative (a lifted wheel) is 0 and the others are scaled so that the four carry m g."""
    free = Wheels(jnp.zeros(4), jnp.zeros(()), jnp.zeros(()))
    return _loads(body(mass, 1.0, cg_height, chassis, free, 1.0, TIME_STEP), accel[0], accel[1])


def _forces(b: Body, ul, ut, fz):
    """The tyre law (the module's docstring): each wheel's force along and across it (4,), (4,), and the
    unregularized power the four dissipate, from the wheels' velocities over the road along and across them
    (4,), (4,) and their loads (4,)."""
    speed2 = ul * ul + ut * ut
    locked = -b.friction * fz / jnp.sqrt(speed2 + b.locked_speed2)  # sliding friction against the whole velocity
    roll = -b.rolling * fz * ul / jnp.sqrt(ul * ul + b.rolling_speed2)
    slip = ut / jnp.sqrt(ul * ul + b.slip_speed2)  # tan of the slip angle: the same at small slip
    has_grip = b.grip > 0
    grip = jnp.where(has_grip, b.grip, 1.0)
    side = -fz * jnp.where(has_grip, grip * jnp.tanh(CORNERING * slip / grip), 0.0)
    free = 1.0 - b.brake
    along = free * roll + b.brake * locked * ul
    across = free * side + b.brake * locked * ut
    power = free * (b.rolling * fz * jnp.abs(ul) + jnp.abs(side) * jnp.abs(ut)) \
        + b.brake * b.friction * fz * la.safe_sqrt(speed2)
    return along, across, jnp.sum(power)


def tyre_forces(velocity_wheel, loads, wheels: Wheels, friction, dt):
    """(4, 2) forces in each wheel's frame (rolling direction, lateral left +) and the unregularized power they
    dissipate, from the wheels' (4, 2) velocities over the road in their own frames and their (4,) loads."""
    b = body(1.0, 1.0, 0.0, Chassis(jnp.asarray(2.8), jnp.asarray(1.6), jnp.asarray(1.2)), wheels, friction, dt)
    along, across, power = _forces(b, velocity_wheel[:, 0], velocity_wheel[:, 1], loads)
    return jnp.stack([along, across], axis=-1), power


def _step(b: Body, carry: _Carry, dt):
    """One step of the integration (the module's docstring): the new carry."""
    state = carry.state
    vx, vy, r = state.velocity[0], state.velocity[1], state.yaw_rate
    s, c = la.sincos(state.yaw)
    u, v = c * vx + s * vy, c * vy - s * vx  # the CG's velocity in the body frame
    wx, wy = u - r * b.y, v + r * b.x  # each wheel's, in the body frame
    ul, ut = b.cos_steer * wx + b.sin_steer * wy, b.cos_steer * wy - b.sin_steer * wx  # in the wheel's frame
    along, across, power = _forces(b, ul, ut, _loads(b, carry.accel[0], carry.accel[1]))
    fx, fy = b.cos_steer * along - b.sin_steer * across, b.sin_steer * along + b.cos_steer * across
    fu, fv, mz = jnp.sum(fx), jnp.sum(fy), jnp.sum(b.x * fy - b.y * fx)
    q = jnp.stack([vx, vy, r])
    m = jnp.stack([b.mass, b.mass, b.izz])
    dq = dt * jnp.stack([c * fu - s * fv, s * fu + c * fv, mz]) / m
    # never more kinetic energy: scale the change back to the least energy along it where it overshoots
    scale = jnp.clip(la.safe_div(-jnp.sum(q * m * dq), jnp.sum(dq * m * dq), 1.0), 0.0, 1.0)
    # the fraction of the step during which the vehicle moves: 2 E / (P dt), at most 1
    energy2 = jnp.sum(m * q * q)
    reach = power * dt
    phi = jnp.where(energy2 >= reach, jnp.where(energy2 > 0, 1.0, 0.0), la.safe_div(energy2, reach, 0.0))
    h = phi * dt
    # at rest from the step in which it stops: what the rules above leave is below one step's dissipation, and
    # its creep would only carry derivatives that grow without bound as the speed decays
    stopped = phi < 1.0
    q_new = jnp.where(stopped, 0.0, q + scale * dq)
    v_mean = 0.5 * (state.velocity + q_new[:2])
    new = Planar(state.position + h * v_mean, state.yaw + h * 0.5 * (r + q_new[2]), q_new[:2], q_new[2])
    travelled = h * la.safe_sqrt(jnp.sum(v_mean * v_mean))
    accel = jnp.where(stopped, 0.0, scale * jnp.stack([fu, fv]) / b.mass)
    return _Carry(new, accel, carry.time + h, carry.distance + travelled, phi)


def step(mass, izz, cg_height, chassis, wheels, friction, carry: _Carry, dt):
    """One step of the integration (the module's docstring) from ``carry``: the new carry."""
    return _step(body(mass, izz, cg_height, chassis, wheels, friction, dt), carry, dt)


def steps_for(time_limit: float, dt: float) -> int:
    """The number of steps that reach ``time_limit`` at step ``dt`` (static)."""
    return max(1, math.ceil(time_limit / dt - 1e-9))


WHILE_CHUNK = 25  # steps between two tests of "all at rest" in the forward-only loop


def to_rest(mass, izz, cg_height, chassis: Chassis, wheels: Wheels, friction, start: Planar, *,
            dt: float = TIME_STEP, time_limit: float = TIME_LIMIT, path: bool = False,
            reverse: bool = False) -> RestResult:
    """A vehicle's motion from ``start`` to rest (``RestResult``).

    ``dt``, ``time_limit`` (s), ``path`` and ``reverse`` are static. ``path``: keep the state after every step
    (the result's ``path``; for a picture: a sweep or a fit keeps none).

    Without a path, and ``reverse`` False, the steps run in a ``lax.while_loop`` that ends when the vehicle
    (under ``jax.vmap``: every vehicle of the batch) is at rest, or at the time limit: values and forward-mode
    derivatives (``jax.jvp``, ``jax.jacfwd``, as the fit uses) of a motion that stops early cost only its
    steps. Reverse-mode differentiation (``jax.grad``, ``jax.vjp``) cannot pass a while loop: ``reverse`` True
    runs every step to the limit in a ``lax.scan`` cut into chunks, each recomputed in the backward pass
    (``jax.checkpoint``), so that a gradient stores about 2 sqrt(n) states instead of n."""
    n = steps_for(time_limit, dt)
    zero = jnp.zeros_like(start.yaw)
    carry = _Carry(start, jnp.zeros_like(start.velocity), zero, zero, jnp.ones_like(zero))
    b = body(mass, izz, cg_height, chassis, wheels, friction, dt)

    def one(c, _):
        c = _step(b, c, dt)
        return c, (jnp.stack([c.time, c.state.position[0], c.state.position[1], c.state.yaw]) if path else None)

    def steps(carry, count):
        return jax.lax.scan(one, carry, None, length=count)[0]

    samples = None
    if path:
        final, samples = jax.lax.scan(one, carry, None, length=n)
        first = jnp.stack([zero, start.position[0], start.position[1], start.yaw])
        samples = jnp.concatenate([first[None], samples], axis=0)
    elif not reverse:
        count, rest = divmod(n, WHILE_CHUNK)
        _, final = jax.lax.while_loop(lambda kc: (kc[0] < count) & (kc[1].moving >= 1.0),
                                      lambda kc: (kc[0] + 1, steps(kc[1], WHILE_CHUNK)), (0, carry))
        if rest:  # the steps left to the limit (a vehicle at rest stays so)
            final = steps(final, rest)
    else:
        chunk = max(1, round(math.sqrt(n)))
        count, rest = divmod(n, chunk)
        final, _ = jax.lax.scan(jax.checkpoint(lambda c, _: (steps(c, chunk), None)), carry, None, length=count)
        if rest:
            final = steps(final, rest)
    end = final.state
    turned = end.yaw - start.yaw
    return RestResult(end.position, la.degrees_0_360(jnp.arctan2(jnp.sin(end.yaw), jnp.cos(end.yaw))),
                      jnp.degrees(turned), final.time, final.distance, final.moving < 1.0, samples)
