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


def wheel_loads(mass, cg_height, chassis: Chassis, accel):
    """(4,) vertical loads, N: the static split by axle, halved per side, plus the load transfer of the body
    frame acceleration ``accel`` (2,) (longitudinal, lateral left +) at ``cg_height``. A load that transfer
    would make negative (a lifted wheel) is 0 and the others are scaled so that the four carry m g."""
    a, L, t = chassis.cg_to_front_axle, chassis.wheelbase, chassis.track
    weight = mass * G0
    front, rear = weight * (L - a) / L, weight * a / L
    pitch = mass * accel[0] * cg_height / L  # moves load from the front axle to the rear under acceleration
    lateral = mass * accel[1] * cg_height / t  # moves load to the right (y < 0) wheels when turning left
    share = jnp.stack([(L - a) / L, (L - a) / L, a / L, a / L])
    side = jnp.array([-1.0, 1.0, -1.0, 1.0], dtype=share.dtype)
    static = 0.5 * jnp.stack([front, front, rear, rear])
    loads = static + 0.5 * pitch * jnp.array([-1.0, -1.0, 1.0, 1.0], dtype=share.dtype) + side * lateral * share
    loads = jnp.maximum(loads, 0.0)
    return loads * weight / jnp.sum(loads)


def _direction(v, a):
    """v / sqrt(|v|^2 + a^2) for (..., k) vectors: the unit direction of v, regularized within speed a."""
    return v / jnp.sqrt(jnp.sum(v * v, axis=-1, keepdims=True) + a * a)


def tyre_forces(velocity_wheel, loads, wheels: Wheels, friction, dt):
    """(4, 2) forces in each wheel's frame (rolling direction, lateral left +) and (4,) the unregularized
    power they dissipate, from the wheels' (4, 2) velocities over the road in their own frames (see the
    module's docstring)."""
    ul, ut = velocity_wheel[:, 0], velocity_wheel[:, 1]
    f = wheels.rolling_resistance
    b = jnp.clip(wheels.brake, 0.0, 1.0)
    step = G0 * dt
    # locked: sliding friction against the wheel's whole velocity
    locked_dir = _direction(velocity_wheel, REGULARIZATION * friction * step)
    locked = -friction * loads[:, None] * locked_dir
    # free: rolling resistance along, a saturating slip-angle force across
    roll = -f * loads * ul / jnp.sqrt(ul * ul + (REGULARIZATION * f * step) ** 2)
    lateral_limit = la.safe_sqrt(jnp.maximum(friction * friction - f * f, 0.0))
    slip = ut / jnp.sqrt(ul * ul + (CORNERING * step) ** 2)  # tan of the slip angle: the same at small slip
    grip = jnp.where(lateral_limit > 0, lateral_limit, 1.0)
    side = -loads * jnp.where(lateral_limit > 0, grip * jnp.tanh(CORNERING * slip / grip), 0.0)
    free = jnp.stack([roll, side], axis=-1)
    force = (1.0 - b)[:, None] * free + b[:, None] * locked
    speed = la.safe_sqrt(jnp.sum(velocity_wheel * velocity_wheel, axis=-1))
    power = (1.0 - b) * (f * loads * jnp.abs(ul) + jnp.abs(side) * jnp.abs(ut)) + b * friction * loads * speed
    return force, power


def _rotate(v, c, s):
    """(..., 2) vectors rotated by the angle whose cosine and sine are c, s."""
    return jnp.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def generalized_force(mass, izz, cg_height, chassis, wheels, friction, state: Planar, accel, dt):
    """(Fx, Fy, Mz) global on the vehicle, the body frame acceleration (2,) they give, and their
    unregularized dissipated power."""
    s, c = la.sincos(state.yaw)
    body_v = _rotate(state.velocity, c, -s)  # global -> body
    r = state.yaw_rate
    p = wheel_positions(chassis)
    w_body = body_v[None, :] + r * jnp.stack([-p[:, 1], p[:, 0]], axis=-1)
    ss, cs = la.sincos(wheels.steer)
    steer_c = jnp.stack([cs, cs, jnp.ones_like(cs), jnp.ones_like(cs)])
    steer_s = jnp.stack([ss, ss, jnp.zeros_like(ss), jnp.zeros_like(ss)])
    w_wheel = _rotate(w_body, steer_c, -steer_s)
    loads = wheel_loads(mass, cg_height, chassis, accel)
    f_wheel, power = tyre_forces(w_wheel, loads, wheels, friction, dt)
    f_body = _rotate(f_wheel, steer_c, steer_s)
    total_body = jnp.sum(f_body, axis=0)
    moment = jnp.sum(p[:, 0] * f_body[:, 1] - p[:, 1] * f_body[:, 0])
    total = _rotate(total_body, c, s)
    return jnp.stack([total[0], total[1], moment]), total_body / mass, jnp.sum(power)


def step(mass, izz, cg_height, chassis, wheels, friction, carry: _Carry, dt):
    """One step of the integration (the module's docstring): the new carry."""
    state = carry.state
    q = jnp.stack([state.velocity[0], state.velocity[1], state.yaw_rate])
    m = jnp.stack([mass, mass, izz])
    force, accel, power = generalized_force(mass, izz, cg_height, chassis, wheels, friction, state, carry.accel, dt)
    dq = dt * force / m
    # never more kinetic energy: scale the change back to the least energy along it where it overshoots
    along = jnp.sum(q * m * dq)
    curvature = jnp.sum(dq * m * dq)
    least = la.safe_div(-along, curvature, 1.0)
    scale = jnp.clip(least, 0.0, 1.0)
    q_new = q + scale * dq
    # the fraction of the step during which the vehicle moves: 2 E / (P dt), at most 1
    energy2 = jnp.sum(m * q * q)
    reach = power * dt
    phi = jnp.where(energy2 >= reach, jnp.where(energy2 > 0, 1.0, 0.0), la.safe_div(energy2, reach, 0.0))
    h = phi * dt
    # at rest from the step in which it stops: what the rules above leave is below one step's dissipation, and
    # its creep would only carry derivatives that grow without bound as the speed decays
    q_new = jnp.where(phi < 1.0, 0.0, q_new)
    v_mean = 0.5 * (state.velocity + q_new[:2])
    new = Planar(state.position + h * v_mean, state.yaw + h * 0.5 * (state.yaw_rate + q_new[2]), q_new[:2], q_new[2])
    travelled = h * la.safe_sqrt(jnp.sum(v_mean * v_mean))
    return _Carry(new, jnp.where(phi < 1.0, 0.0, scale * accel), carry.time + h, carry.distance + travelled, phi)


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

    def one(c, _):
        c = step(mass, izz, cg_height, chassis, wheels, friction, c, dt)
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
