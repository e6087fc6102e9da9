"""Post-impact motion to rest, one step: one vehicle on a flat road, planar, four wheels (docs/model.md, "Motion to
rest"). The loops that run the steps are ``motion_loop``'s.

State: the CG's position (x, y), yaw, the CG's velocity (vx, vy) and yaw rate, global. Each wheel
carries a vertical load (the static split by axle, plus longitudinal and lateral load transfer from the
CG's height and the vehicle's acceleration) and a tyre force inside its friction circle:

- ``free`` (brake fraction 0): rolling resistance f Fz against the wheel's rolling direction, and a
  lateral force from the slip angle alpha, mu' Fz tanh(k alpha / mu') (k = ``CORNERING``, mu' the
  friction left by rolling resistance): linear at small slip, saturating at the friction circle;
- ``locked`` (brake fraction 1): mu Fz against the wheel's velocity over the road;
- braked by a fraction b: (1 - b) of the free force plus b of the locked one, inside the circle
  because both are.

Integration: a fixed step ``dt`` (``TIME_STEP`` by default). Velocities take the step's
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

Derivatives: forward mode (``jax.jvp``, ``jax.jacfwd``, as the fit and the posterior take them) goes through
the steps by JAX's own rules, in the while loop that stops at rest. Reverse mode needs the scan that runs every
step (``motion_loop.to_rest(reverse=True)``); its steps carry a hand-written adjoint (``_step_bwd``) that reads back the
step's costly values. ``_advance`` names those values (``checkpoint_name``), so that JAX's adjoint of the step
under ``jax.checkpoint`` with ``save_only_these_names`` can be set beside it: that costs two to three times the
hand adjoint's time, whichever values it saves (``_step_reverse``).

Everything here is pure and unbatched: jit, vmap and differentiate at the edge.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.ad_checkpoint import checkpoint_name

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
    (``motion_loop.to_rest(path=True)``) the state at the start and after every step, (steps + 1, 4): time s, x m, y m,
    yaw rad."""

    rest_position: jnp.ndarray
    rest_yaw: jnp.ndarray
    rotation_to_rest: jnp.ndarray
    time_to_rest: jnp.ndarray
    distance_to_rest: jnp.ndarray
    at_rest: jnp.ndarray
    path: jnp.ndarray | None = None


class Carry(NamedTuple):
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
                _regularizing(friction, step), _regularizing(f, step), (CORNERING * step) ** 2)


def _regularizing(coefficient, step):
    """The square of a friction direction's regularizing speed, REGULARIZATION of the speed a force of
    ``coefficient`` m g changes in one step; 1 (m/s)^2 where the coefficient is 0 (a frictionless road, or no
    rolling resistance): no force then, whose direction the stand-in keeps finite at rest."""
    return jnp.where(coefficient > 0, (REGULARIZATION * coefficient * step) ** 2, 1.0)


def _loads(b: Body, ax, ay):
    """(4,) vertical loads at the body frame acceleration (ax, ay): a load that transfer would make negative (a
    lifted wheel) is 0, and the others are scaled so that the four carry m g. Also the loads before that scaling
    (4,) and their sum (the step's adjoint reads them)."""
    loads = jnp.maximum(b.static + b.pitch * ax + b.lateral * ay, 0.0)
    total = jnp.sum(loads)
    return loads * b.weight / total, loads, total


def wheel_loads(mass, cg_height, chassis: Chassis, accel):
    """(4,) vertical loads, N: the static split by axle, halved per side, plus the load transfer of the body
    frame acceleration ``accel`` (2,) (longitudinal, lateral left +) at ``cg_height``. A load that transfer
    would make negative (a lifted wheel) is 0 and the others are scaled so that the four carry m g."""
    free = Wheels(jnp.zeros(4), jnp.zeros(()), jnp.zeros(()))
    return _loads(body(mass, 1.0, cg_height, chassis, free, 1.0, TIME_STEP), accel[0], accel[1])[0]


class _Forces(NamedTuple):
    """The tyre law's values at one step, each (4,) (``_tyres``): what the forces are made of, kept for the
    step's adjoint (``_step_bwd``)."""

    along: jnp.ndarray  # the force along the wheel
    across: jnp.ndarray  # the force across it
    power: jnp.ndarray  # the unregularized power each wheel dissipates
    locked: jnp.ndarray  # -mu Fz / |v|_reg: the locked force per unit of the wheel's velocity
    roll: jnp.ndarray  # the rolling resistance force
    side: jnp.ndarray  # the free wheel's lateral force
    inv_locked: jnp.ndarray  # 1 / sqrt(|v|^2 + a_locked^2)
    inv_rolling: jnp.ndarray  # 1 / sqrt(ul^2 + a_rolling^2)
    inv_slip: jnp.ndarray  # 1 / sqrt(ul^2 + a_slip^2)
    tanh: jnp.ndarray  # tanh(k slip / mu')
    speed: jnp.ndarray  # |v| (safe_sqrt)


def _grip(b: Body):
    """Where the free wheels have lateral grip (mu > f), and that grip (1 where there is none, a stand-in)."""
    has_grip = b.grip > 0
    return has_grip, jnp.where(has_grip, b.grip, 1.0)


def _tyre_terms(b: Body, fz, ul, inv_locked, inv_rolling, tanh):
    """The locked force per unit of the wheel's velocity (-mu Fz / |v|), the rolling resistance force and the
    free wheel's lateral force (4,) each, from the loads, the rolling speeds, and the tyre law's regularized
    inverse speeds and tanh (``_tyres``)."""
    has_grip, grip = _grip(b)
    locked = -b.friction * fz * inv_locked  # sliding friction against the whole velocity
    roll = -b.rolling * fz * ul * inv_rolling
    side = -fz * jnp.where(has_grip, grip * tanh, 0.0)
    return locked, roll, side


def _tyres(b: Body, ul, ut, fz) -> _Forces:
    """The tyre law (the module's docstring) from the wheels' velocities over the road along and across them
    (4,), (4,) and their loads (4,)."""
    speed2 = ul * ul + ut * ut
    inv_locked = checkpoint_name(1.0 / jnp.sqrt(speed2 + b.locked_speed2), "motion.inv_locked")
    inv_rolling = checkpoint_name(1.0 / jnp.sqrt(ul * ul + b.rolling_speed2), "motion.inv_rolling")
    inv_slip = checkpoint_name(1.0 / jnp.sqrt(ul * ul + b.slip_speed2), "motion.inv_slip")
    slip = ut * inv_slip  # tan of the slip angle: the same at small slip
    tanh = checkpoint_name(jnp.tanh(CORNERING * slip / _grip(b)[1]), "motion.tanh")
    locked, roll, side = _tyre_terms(b, fz, ul, inv_locked, inv_rolling, tanh)
    free = 1.0 - b.brake
    along = free * roll + b.brake * locked * ul
    across = free * side + b.brake * locked * ut
    speed = checkpoint_name(la.safe_sqrt(speed2), "motion.speed")
    power = free * (b.rolling * fz * jnp.abs(ul) + jnp.abs(side) * jnp.abs(ut)) + b.brake * b.friction * fz * speed
    return _Forces(along, across, power, locked, roll, side, inv_locked, inv_rolling, inv_slip, tanh, speed)


def _forces(b: Body, ul, ut, fz):
    """The tyre law: each wheel's force along and across it (4,), (4,), and the unregularized power the four
    dissipate (``_tyres``)."""
    f = _tyres(b, ul, ut, fz)
    return f.along, f.across, jnp.sum(f.power)


def tyre_forces(velocity_wheel, loads, wheels: Wheels, friction, dt):
    """(4, 2) forces in each wheel's frame (rolling direction, lateral left +) and the unregularized power they
    dissipate, from the wheels' (4, 2) velocities over the road in their own frames and their (4,) loads."""
    b = body(1.0, 1.0, 0.0, Chassis(jnp.asarray(2.8), jnp.asarray(1.6), jnp.asarray(1.2)), wheels, friction, dt)
    along, across, power = _forces(b, velocity_wheel[:, 0], velocity_wheel[:, 1], loads)
    return jnp.stack([along, across], axis=-1), power


def _wheel_velocities(b: Body, sin, cos, velocity, yaw_rate):
    """Each wheel's velocity over the road (4,): in the body frame (wx, wy), and in its own (ul along it, ut
    across it), from the yaw's sine and cosine and the CG's global velocity (2,) and yaw rate."""
    vx, vy = velocity[0], velocity[1]
    u, v = cos * vx + sin * vy, cos * vy - sin * vx  # the CG's velocity in the body frame
    wx, wy = u - yaw_rate * b.y, v + yaw_rate * b.x
    return wx, wy, b.cos_steer * wx + b.sin_steer * wy, b.cos_steer * wy - b.sin_steer * wx


def _steered(b: Body, along, across):
    """The wheels' forces (4,) along and across them turned into the body frame (fx, fy)."""
    return b.cos_steer * along - b.sin_steer * across, b.sin_steer * along + b.cos_steer * across


class _Saved(NamedTuple):
    """What the step's adjoint (``_step_bwd``) reads back of its forward (``_advance``): the costly values (the
    square roots, tanh, sine and cosine, the quotients) and those that many of its terms read. It derives the
    others in a few operations each: recomputing more of the step there costs more than storing it."""

    velocity: jnp.ndarray  # (2,) the CG's velocity at the start of the step
    yaw_rate: jnp.ndarray  # at the start
    accel: jnp.ndarray  # (2,) the last step's acceleration (load transfer)
    sin: jnp.ndarray
    cos: jnp.ndarray
    ul: jnp.ndarray  # (4,) the wheels' velocities along and across them
    ut: jnp.ndarray
    loads: jnp.ndarray  # (4,) the loads before they are scaled to m g
    total: jnp.ndarray  # their sum
    along: jnp.ndarray  # (4,) the tyre forces along and across the wheels
    across: jnp.ndarray
    inv_locked: jnp.ndarray  # (4,) the tyre law's values (_Forces)
    inv_rolling: jnp.ndarray
    inv_slip: jnp.ndarray
    tanh: jnp.ndarray
    speed: jnp.ndarray
    force: jnp.ndarray  # (3,) fu, fv, mz: the body frame force and the yaw moment
    dq: jnp.ndarray  # (3,) the step's change of (vx, vy, r) before it is scaled back
    raw: jnp.ndarray  # the energy rule's scale before its clip to [0, 1]
    energy2: jnp.ndarray  # 2 E
    reach: jnp.ndarray  # P dt
    phi: jnp.ndarray
    new_yaw_rate: jnp.ndarray
    v_mean: jnp.ndarray  # (2,) the step's mean velocity
    inv_v_mean: jnp.ndarray  # 1 / |v_mean|, 0 where safe_sqrt's gradient is 0


def _advance(b: Body, carry: Carry, dt):
    """One step of the integration (the module's docstring): the new carry, and what the step's adjoint reads."""
    state = carry.state
    vx, vy, r = state.velocity[0], state.velocity[1], state.yaw_rate
    s, c = checkpoint_name(la.sincos(state.yaw), "motion.sincos")
    _, _, ul, ut = checkpoint_name(_wheel_velocities(b, s, c, state.velocity, r), "motion.wheel_velocities")
    fz, loads, total = checkpoint_name(_loads(b, carry.accel[0], carry.accel[1]), "motion.loads")
    t = _tyres(b, ul, ut, fz)
    power = jnp.sum(t.power)
    fx, fy = _steered(b, *checkpoint_name((t.along, t.across), "motion.tyre_forces"))
    fu, fv, mz = checkpoint_name((jnp.sum(fx), jnp.sum(fy), jnp.sum(b.x * fy - b.y * fx)), "motion.force")
    q = jnp.stack([vx, vy, r])
    m = jnp.stack([b.mass, b.mass, b.izz])
    dq = checkpoint_name(dt * jnp.stack([c * fu - s * fv, s * fu + c * fv, mz]) / m, "motion.dq")
    energy2, reach = checkpoint_name((jnp.sum(m * q * q), power * dt), "motion.energy")
    # never more kinetic energy: scale the change back to the least energy along it where it overshoots. The whole
    # change where it cannot overshoot (the quotient is 1 or more), and where it is below rounding next to the
    # velocities (|dq| < eps |q| in the mass metric): there the quotient's derivative, as 1 / (dq m dq)^2, overflows
    # (a car rolling straight on without rolling resistance, the tyres damping its yaw rate geometrically toward 0),
    # while any scale gives the same new velocities to rounding
    num, den = -jnp.sum(q * m * dq), jnp.sum(dq * m * dq)
    full = (num >= den) | (den <= jnp.finfo(den.dtype).eps ** 2 * energy2)
    raw = checkpoint_name(jnp.where(full, 1.0, num / jnp.where(full, 1.0, den)), "motion.raw")
    scale = jnp.clip(raw, 0.0, 1.0)
    # the fraction of the step during which the vehicle moves: 2 E / (P dt), at most 1
    phi = jnp.where(energy2 >= reach, jnp.where(energy2 > 0, 1.0, 0.0), la.safe_div(energy2, reach, 0.0))
    phi = checkpoint_name(phi, "motion.phi")
    h = phi * dt
    # at rest from the step in which it stops: what the rules above leave is below one step's dissipation, and
    # its creep would only carry derivatives that grow without bound as the speed decays
    stopped = phi < 1.0
    q_new = checkpoint_name(jnp.where(stopped, 0.0, q + scale * dq), "motion.q_new")
    v_mean = checkpoint_name(0.5 * (state.velocity + q_new[:2]), "motion.v_mean")
    new = Planar(state.position + h * v_mean, state.yaw + h * 0.5 * (r + q_new[2]), q_new[:2], q_new[2])
    mean2 = jnp.sum(v_mean * v_mean)
    travelled = h * checkpoint_name(la.safe_sqrt(mean2), "motion.mean_speed")
    accel = jnp.where(stopped, 0.0, scale * jnp.stack([fu, fv]) / b.mass)
    tiny = jnp.finfo(mean2.dtype).tiny
    inv_v_mean = checkpoint_name(jnp.where(mean2 > tiny, 1.0 / jnp.sqrt(jnp.maximum(mean2, tiny)), 0.0),
                                 "motion.inv_v_mean")
    saved = _Saved(state.velocity, r, carry.accel, s, c, ul, ut, loads, total, t.along, t.across, t.inv_locked,
                   t.inv_rolling, t.inv_slip, t.tanh, t.speed, jnp.stack([fu, fv, mz]), dq, raw, energy2, reach,
                   phi, q_new[2], v_mean, inv_v_mean)
    return Carry(new, accel, carry.time + h, carry.distance + travelled, phi), saved


def _step(b: Body, carry: Carry, dt):
    """One step of the integration (the module's docstring): the new carry. Differentiable both ways by JAX's
    own rules: the forward loop's derivatives (``jax.jvp``) go through this."""
    return _advance(b, carry, dt)[0]


@functools.partial(jax.custom_vjp, nondiff_argnums=(2,))
def _step_reverse(b: Body, carry: Carry, dt):
    """``_step``, whose reverse-mode derivative is the hand-written adjoint ``_step_bwd``, which reads back the
    step's ``_Saved`` values. First-order reverse mode only (``jax.grad``, ``jax.vjp``, ``jax.jacrev``): forward
    mode cannot pass a custom VJP (it goes through ``_step``, in ``motion_loop.to_rest(reverse=False)``), and the
    adjoint's stored values (``la.materialize``) have no derivative.

    Why by hand, though a change to the tyre law must then be made in ``_advance`` and in ``_step_bwd``: JAX's own
    adjoint of the step, with its many stored or recomputed intermediates, costs several forward steps more, and
    under ``jax.checkpoint`` it still costs two to three times the hand adjoint's gradient time, whether its policy
    (``jax.checkpoint_policies.save_only_these_names``) saves the values ``_advance`` names as costly (its square
    roots, tanh, sine and cosine), every value the hand adjoint stores, or nothing; the scratch memory is the
    same in all. The figures and their date: docs/performance.md ("Motion to rest") and
    benchmarks/bench_motion_adjoint.py, whose command is
    ``python benchmarks/bench_motion_adjoint.py [--pairs 100000] [--seconds 3] [--repeats 3]``."""
    return _step(b, carry, dt)


def _step_fwd(b: Body, carry: Carry, dt):
    new, saved = _advance(b, carry, dt)
    return new, (b, saved)


def _integration_adjoint(b: Body, sv: _Saved, ct: Carry, dt):
    """The first half of ``_step_bwd``, the integration's rules taken back: from the cotangents of the new carry,
    those of the body frame force and yaw moment (fu, fv, mz), of the power, of the state's velocities and yaw
    rate (3,), of the yaw's cosine and sine, and of the mass and yaw inertia."""
    vx, vy, r = sv.velocity[0], sv.velocity[1], sv.yaw_rate
    s, c, phi = sv.sin, sv.cos, sv.phi
    scale = jnp.clip(sv.raw, 0.0, 1.0)
    h = phi * dt
    moving = phi >= 1.0  # not stopped: the new velocities and acceleration follow the step
    fu, fv = sv.force[0], sv.force[1]
    q = jnp.stack([vx, vy, r])
    m = jnp.stack([b.mass, b.mass, b.izz])
    a_pos, a_yaw = ct.state.position, ct.state.yaw
    # the new time, distance, position and yaw: t + h, d + h |v_mean|, p + h v_mean, yaw + h (r + r') / 2
    speed = la.mm(sv.v_mean, sv.v_mean * sv.inv_v_mean)
    a_h = ct.time + ct.distance * speed + la.mm(a_pos, sv.v_mean) + a_yaw * 0.5 * (r + sv.new_yaw_rate)
    a_vmean = h * a_pos + ct.distance * h * sv.v_mean * sv.inv_v_mean
    a_qnew = jnp.concatenate([ct.state.velocity + 0.5 * a_vmean, (ct.state.yaw_rate + 0.5 * h * a_yaw)[None]])
    a_velocity = 0.5 * a_vmean
    a_r = 0.5 * h * a_yaw
    # the new acceleration scale (fu, fv) / m and the new velocities q + scale dq, where still moving
    a_acc = jnp.where(moving, ct.accel, 0.0)
    a_qnew = jnp.where(moving, a_qnew, 0.0)
    a_scale = la.mm(a_acc, sv.force[:2]) / b.mass + la.mm(a_qnew, sv.dq)
    a_fu, a_fv = a_acc[0] * scale / b.mass, a_acc[1] * scale / b.mass
    a_mass = -la.mm(a_acc, sv.force[:2]) * scale / (b.mass * b.mass)
    a_q = a_qnew
    a_dq = a_qnew * scale
    # phi: 1 or 0 where 2 E >= P dt, else 2 E / (P dt); h = phi dt
    a_phi = ct.moving + dt * a_h
    partial = sv.energy2 < sv.reach
    reach = jnp.where(partial, sv.reach, 1.0)
    a_energy2 = jnp.where(partial, a_phi / reach, 0.0)
    a_power = jnp.where(partial, -a_phi * sv.energy2 / (reach * reach), 0.0) * dt
    a_q = a_q + 2.0 * m * q * a_energy2
    a_m = q * q * a_energy2
    # scale = clip(-(q m dq) / (dq m dq), 0, 1)
    den = jnp.sum(sv.dq * m * sv.dq)
    inside = (den != 0) & (sv.raw > 0.0) & (sv.raw < 1.0)
    den = jnp.where(inside, den, 1.0)
    a_num = jnp.where(inside, a_scale / den, 0.0)
    a_den = -a_num * sv.raw
    a_q = a_q - a_num * m * sv.dq
    a_m = a_m - a_num * q * sv.dq + a_den * sv.dq * sv.dq
    a_dq = a_dq - a_num * q * m + 2.0 * a_den * m * sv.dq
    # dq = dt (c fu - s fv, s fu + c fv, mz) / m
    a_g = a_dq * dt / m
    a_m = a_m - a_dq * sv.dq / m
    a_fu = a_fu + c * a_g[0] + s * a_g[1]
    a_fv = a_fv - s * a_g[0] + c * a_g[1]
    a_mz = a_g[2]
    a_c = a_g[0] * fu + a_g[1] * fv
    a_s = a_g[1] * fu - a_g[0] * fv
    a_mass = a_mass + a_m[0] + a_m[1]
    a_izz = a_m[2]
    a_q = a_q + jnp.concatenate([a_velocity, a_r[None]])
    return a_fu, a_fv, a_mz, a_power, a_q, a_c, a_s, a_mass, a_izz


def _step_bwd(dt, residuals, ct: Carry):
    """The adjoint of ``_advance``: the cotangents of the body and of the carry from those of the new carry,
    the forward's operations taken back in reverse order (``a_x`` is the cotangent of x). The integration's
    rules first (``_integration_adjoint``), then the forces' sums, the tyre law, the loads and the wheels'
    velocities."""
    b, sv = residuals
    vx, vy, r = sv.velocity[0], sv.velocity[1], sv.yaw_rate
    s, c, ul, ut = sv.sin, sv.cos, sv.ul, sv.ut
    a_fu, a_fv, a_mz, a_power, a_q, a_c, a_s, a_mass, a_izz = _integration_adjoint(b, sv, ct, dt)
    # fu, fv, mz: sums of fx, fy and x fy - y fx; fx, fy: the wheels' forces turned by their steer
    fx, fy = _steered(b, sv.along, sv.across)
    a_fx = a_fu - b.y * a_mz
    a_fy = a_fv + b.x * a_mz
    a_x = fy * a_mz
    a_y = -fx * a_mz
    a_along = b.cos_steer * a_fx + b.sin_steer * a_fy
    a_across = b.cos_steer * a_fy - b.sin_steer * a_fx
    a_cos_steer = sv.along * a_fx + sv.across * a_fy
    a_sin_steer = sv.along * a_fy - sv.across * a_fx
    # stored once: XLA's CPU fusion would otherwise recompute these chains in each sum over the wheels below
    a_along, a_across = la.materialize(a_along, a_across)
    # the tyre law (_tyres)
    fz = sv.loads * (b.weight / sv.total)
    locked, roll, side = _tyre_terms(b, fz, ul, sv.inv_locked, sv.inv_rolling, sv.tanh)
    brake, free = b.brake, 1.0 - b.brake
    a_pw = a_power
    abs_ul, abs_ut, abs_side = jnp.abs(ul), jnp.abs(ut), jnp.abs(side)
    a_free = a_along * roll + a_across * side + a_pw * (b.rolling * fz * abs_ul + abs_side * abs_ut)
    a_brake = (a_along * locked * ul + a_across * locked * ut + a_pw * b.friction * fz * sv.speed) - a_free
    a_roll = a_along * free
    a_side = a_across * free + a_pw * free * abs_ut * jnp.sign(side)
    a_locked = brake * (a_along * ul + a_across * ut)
    a_ul = a_along * brake * locked + a_pw * free * b.rolling * fz * jnp.sign(ul)
    a_ut = a_across * brake * locked + a_pw * free * abs_side * jnp.sign(ut)
    a_rolling = jnp.sum(a_pw * free * fz * abs_ul)
    a_friction = jnp.sum(a_pw * brake * fz * sv.speed)
    a_fz = a_pw * (free * b.rolling * abs_ul + brake * b.friction * sv.speed)
    a_speed = a_pw * brake * b.friction * fz
    a_speed2 = jnp.where(sv.speed > 0, 0.5 * a_speed / jnp.where(sv.speed > 0, sv.speed, 1.0), 0.0)
    # side = -fz mu' tanh(k slip / mu') where there is grip
    has_grip, grip = _grip(b)
    a_side = jnp.where(has_grip, a_side, 0.0)
    a_fz = a_fz - a_side * grip * sv.tanh
    a_tanh = -a_side * fz * grip
    a_z = a_tanh * (1.0 - sv.tanh * sv.tanh)
    slip = ut * sv.inv_slip
    a_slip = a_z * CORNERING / grip
    a_grip = jnp.sum(-a_side * fz * sv.tanh - a_z * CORNERING * slip / (grip * grip))
    a_ut = a_ut + a_slip * sv.inv_slip
    a_inv_slip = a_slip * ut
    # roll = -f fz ul / sqrt(ul^2 + a^2), locked = -mu fz / sqrt(|v|^2 + a^2)
    a_rolling = a_rolling - jnp.sum(a_roll * fz * ul * sv.inv_rolling)
    a_fz = a_fz - a_roll * b.rolling * ul * sv.inv_rolling - a_locked * b.friction * sv.inv_locked
    a_ul = a_ul - a_roll * b.rolling * fz * sv.inv_rolling
    a_inv_rolling = -a_roll * b.rolling * fz * ul
    a_friction = a_friction - jnp.sum(a_locked * fz * sv.inv_locked)
    a_inv_locked = -a_locked * b.friction * fz

    def cube(inv):  # d(1 / sqrt(x)) = -dx / (2 sqrt(x)^3)
        return -0.5 * inv * inv * inv

    a_x_slip, a_x_rolling, a_x_locked = (a_inv_slip * cube(sv.inv_slip), a_inv_rolling * cube(sv.inv_rolling),
                                         a_inv_locked * cube(sv.inv_locked))
    a_speed2 = a_speed2 + a_x_locked
    a_ul = a_ul + 2.0 * ul * (a_x_slip + a_x_rolling + a_speed2)
    a_ut = a_ut + 2.0 * ut * a_speed2
    a_fz, a_ul, a_ut = la.materialize(a_fz, a_ul, a_ut)
    # the loads: fz = w max(l, 0) / sum, l = static + pitch ax + lateral ay
    a_weight = jnp.sum(a_fz * sv.loads) / sv.total
    a_loads = b.weight / sv.total * (a_fz - a_weight)
    a_l = jnp.where(sv.loads > 0, a_loads, 0.0)
    a_accel = jnp.stack([jnp.sum(a_l * b.pitch), jnp.sum(a_l * b.lateral)])
    # the wheels' velocities: in their own frames from the body frame, and there from the CG's
    wx, wy, _, _ = _wheel_velocities(b, s, c, sv.velocity, r)
    a_wx = b.cos_steer * a_ul - b.sin_steer * a_ut
    a_wy = b.sin_steer * a_ul + b.cos_steer * a_ut
    a_cos_steer = a_cos_steer + a_ul * wx + a_ut * wy
    a_sin_steer = a_sin_steer + a_ul * wy - a_ut * wx
    a_u, a_v = jnp.sum(a_wx), jnp.sum(a_wy)
    a_r = a_q[2] + jnp.sum(b.x * a_wy - b.y * a_wx)
    a_x = a_x + a_wy * r
    a_y = a_y - a_wx * r
    a_velocity = a_q[:2] + jnp.stack([c * a_u - s * a_v, s * a_u + c * a_v])
    a_c = a_c + a_u * vx + a_v * vy
    a_s = a_s + a_u * vy - a_v * vx
    a_state = Planar(ct.state.position, ct.state.yaw + c * a_s - s * a_c, a_velocity, a_r)
    a_carry = Carry(a_state, a_accel, ct.time, ct.distance, jnp.zeros_like(ct.moving))
    ax, ay = sv.accel[0], sv.accel[1]
    a_body = Body(a_mass, a_izz, a_x, a_y, a_cos_steer, a_sin_steer, a_l, a_l * ax, a_l * ay, a_weight, a_brake,
                  a_rolling, a_friction, jnp.where(has_grip, a_grip, 0.0),
                  jnp.sum(a_x_locked), jnp.sum(a_x_rolling), jnp.sum(a_x_slip))
    return a_body, a_carry


_step_reverse.defvjp(_step_fwd, _step_bwd)


def step(mass, izz, cg_height, chassis, wheels, friction, carry: Carry, dt):
    """One step of the integration (the module's docstring) from ``carry``: the new carry."""
    return _step(body(mass, izz, cg_height, chassis, wheels, friction, dt), carry, dt)


def step_function(reverse: bool = False):
    """The step (b, carry, dt) -> carry that a loop over steps runs: ``_step``, or where the loop is to be
    differentiated in reverse mode, ``_step_reverse`` (its hand-written adjoint)."""
    return _step_reverse if reverse else _step


def start_carry(start: Planar) -> Carry:
    """The integration's carry at ``start``: no acceleration yet, time and distance 0, moving."""
    zero = jnp.zeros_like(start.yaw)
    return Carry(start, jnp.zeros_like(start.velocity), zero, zero, jnp.ones_like(zero))
