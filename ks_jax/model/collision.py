"""One collision: the Kudlich-Slibar impulse exchange (docs/model.md, "The impulse exchange").

    exchange = results(impulse(prepare(inputs)))

- ``prepare``: the input rules (``checks``) and the sines and cosines of both vehicles' attitude;
- ``impulse``: steps 1-6: relative velocity at the centroid, collision matrix (``matrix``), stick
  impulse, friction cone (``cone``), restitution;
- ``results``: everything docs/model.md's "Results" derives from the impulse (``results``).

Pure and unbatched; nothing branches in Python on array values, so under ``jax.vmap`` a row whose
inputs break a rule gets that rule's status code and NaN results while the others are solved. The
three stages are the split that a batched caller may compute apart (``ks_jax.batch``): their outputs
are the numbers that many results read, stored once per row.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax.numpy as jnp

from . import linalg as la
from .checks import benign, check_smoothing, input_status, is_fixed
from .cone import friction_cone
from .matrix import collision_matrix, inverse_inertia_world
from .results import derive, mask_invalid
from .types import INVALID_OVERFLOW, OK, SEPARATING, Contact, ExchangeResult, State, Vehicle


def exchange(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
             smoothing=0.0) -> ExchangeResult:
    """One KS impulse exchange at a given contact: the impulse J on vehicle 1 (-J on vehicle 2) that
    brings the vehicles to a common velocity at the impulse centroid, limited by the friction cone and
    scaled by restitution, and every result derived from it.

    Args (one collision, SI units; a batch is the same with a leading axis, under ``jax.vmap``):
      vehicle1, vehicle2: ``Vehicle``: mass () kg; inertia (3,) principal moments about the CG in the
        body frame or (3, 3) tensor, kg m^2; length, width, height, cg_to_front, cg_height () m.
      state1, state2: ``State`` at the instant of the exchange, global frame: position (3,) m of the CG;
        velocity (3,) m/s; yaw, pitch, roll () rad; angular_velocity (3,) rad/s.
      contact: ``Contact``: point (3,) m, the impulse centroid; normal (3,), from vehicle 2 into vehicle
        1 (normalised here); restitution () in [-1, 1]; friction () >= 0; penetration_time () s (read
        by automatic contact only).
      smoothing: tau in [0, 1): 0 is the exact model; tau > 0 the smooth friction cone (``cone``), O(tau)
        from it and continuously differentiable. A Python number is checked here (ValueError); an array
        is checked per row (status ``INVALID_SMOOTHING``).

    Returns:
      ``ExchangeResult``: ``.contact`` (``ContactResult``: impulse (3,) N s, impulse_magnitude,
      energy_loss J, sliding, status, ...) and ``.vehicles``, a pair of ``VehicleResult`` (delta_v (3,)
      m/s, pdof deg, crush m, ees m/s, velocity_after, yaw_rate_after rad/s, ...). A row whose inputs
      break a rule has that rule's status code (``ks_jax.status_text`` gives the words) and NaN in every
      number; a contact that is not closing has status "separating" and no impulse. Finite inputs whose
      results overflow get ``INVALID_OVERFLOW`` and, as every invalid row, NaN in every number.

    Works under ``jax.jit``, ``jax.vmap``, ``jax.grad`` and ``jax.jacfwd``. ``ks_jax.exchange`` is this
    function with a batching rule for large batches on a CPU (``ks_jax.batch``).

    Example (the Virtual CRASH chapter with the Saturn hit from behind)::

        >>> from ks_jax import Contact, State, Vehicle, exchange
        >>> from ks_jax.units import FT, G0, LBF, MPH
        >>> saturn = Vehicle.create(mass=3183.475 * LBF / G0, inertia=[480, 2250, 2400], length=15.87 * FT,
        ...                         width=5.71 * FT)
        >>> pontiac = Vehicle.create(mass=3496.531 * LBF / G0, inertia=[520, 2500, 2700], length=16.53 * FT,
        ...                          width=6.05 * FT)
        >>> out = exchange(saturn, State.create([3.54, 0, 0.54], speed=5 * MPH), pontiac,
        ...                State.create([-0.98, 0, 0.54], speed=21 * MPH),
        ...                Contact.create([4 * FT, 0, 0.54], azimuth=0.0, restitution=0.1, friction=0.5))
        >>> round(float(out.contact.impulse_magnitude), 2), round(float(out.vehicles[0].delta_v_magnitude / MPH), 2)
        (5946.85, 9.21)
    """
    check_smoothing(smoothing)
    prepared = prepare(vehicle1, state1, vehicle2, state2, contact, smoothing)
    found = impulse(vehicle1, state1, vehicle2, state2, contact, prepared, smoothing)
    return results(vehicle1, state1, vehicle2, state2, contact, prepared, found)


def stages(smoothing=0.0):
    """``exchange`` as its three stages (``prepare``, ``impulse``, ``results``), each called with the five
    inputs and then the outputs of the stages before it: the split that ``ks_jax.batch`` computes apart
    (``ks_jax.batch.stages.run``). ``smoothing``: a Python number in [0, 1), or an array (checked per row)."""
    check_smoothing(smoothing)
    return functools.partial(prepare, smoothing=smoothing), functools.partial(impulse, smoothing=smoothing), results


class Prepared(NamedTuple):
    """``prepare``'s output: status () int32 and trig, for each vehicle ``linalg.trig`` of its angles
    (those of ``checks.benign``: 0 in a row whose inputs break a rule)."""

    status: jnp.ndarray
    trig: tuple


def prepare(vehicle1, state1, vehicle2, state2, contact, smoothing=0.0) -> Prepared:
    """The input rules and the sines and cosines of both vehicles' yaw, pitch and roll."""
    status = input_status(vehicle1, state1, vehicle2, state2, contact, smoothing)
    ok = status == OK

    def trig(s):
        return la.trig(*(jnp.where(ok, a, jnp.zeros_like(a)) for a in (s.yaw, s.pitch, s.roll)))

    return Prepared(status, (trig(state1), trig(state2)))


class Impulse(NamedTuple):
    """``impulse``'s output, what ``results`` derives everything from. Vectors as 3-tuples and matrices as
    rows of 3-tuples (``linalg.vec``, ``linalg.mat``): a batched caller stores each component as one
    array. J = size d with d = n + T / N: size = (1 + eps) N and ratio = |T| / N, from which |J| and
    |J_t| get their one-sided derivatives where they are 0 (``results.derive``). a_i: I_i^-1 in the
    global frame; rot_i: R_i; r_i = P - x_i."""

    j: tuple
    sliding: jnp.ndarray
    approaching: jnp.ndarray
    size: jnp.ndarray
    ratio: jnp.ndarray
    n: tuple
    u: tuple
    a1: tuple
    rot1: tuple
    a2: tuple
    rot2: tuple
    r1: tuple
    r2: tuple


def impulse(vehicle1, state1, vehicle2, state2, contact, prepared: Prepared, smoothing=0.0) -> Impulse:
    """Steps 1-6 of the exchange: the impulse J on vehicle 1, and what the results are derived from."""
    (trig1, trig2), ok = prepared.trig, prepared.status == OK
    vehicle1, state1, vehicle2, state2, contact = benign((vehicle1, state1, vehicle2, state2, contact), ok)
    # |normal| > 0 here (checks, benign); a plain sum, not la.safe_norm, whose expression XLA would copy
    # into every loop that reads n
    n = contact.normal / jnp.sqrt(jnp.sum(contact.normal * contact.normal))
    # 1. the relative velocity at the centroid
    r1, r2 = contact.point - state1.position, contact.point - state2.position
    u = (state1.velocity + la.cross(state1.angular_velocity, r1)) - (
        state2.velocity + la.cross(state2.angular_velocity, r2))
    # 2. the collision matrix: the relative velocity after an impulse J is u + K J
    a1, rot1 = inverse_inertia_world(vehicle1.inertia, trig1)
    a2, rot2 = inverse_inertia_world(vehicle2.inertia, trig2)
    a2 = jnp.where(is_fixed(vehicle2), jnp.zeros_like(a2), a2)  # a fixed object: I^-1 = 0 (and 1/m = 1/inf = 0)
    K = collision_matrix(vehicle1.mass, a1, r1, vehicle2.mass, a2, r2)
    # 3. no exchange unless the bodies approach at the centroid
    un = la.dot(n, u)
    approaching = un < 0
    # 4. the stick impulse, which brings u to 0
    j_stick = -la.matvec(la.adjugate3(K), u) / la.det3(K)
    # 5. its direction limited by the friction cone, d = n + T / N
    d, ratio, sliding = friction_cone(j_stick, n, contact.friction, smoothing)
    # the normal impulse N that brings u.n to 0 along d, then 6. restitution scales the whole vector
    normal = jnp.where(approaching, -un / jnp.where(approaching, la.dot(n, la.matvec(K, d)), 1.0), 0.0)
    size = (1.0 + contact.restitution) * normal
    j = size * d
    return Impulse(la.vec(j), approaching & sliding, approaching, size, ratio, la.vec(n), la.vec(u),
                   la.mat(a1), la.mat(rot1), la.mat(a2), la.mat(rot2), la.vec(r1), la.vec(r2))


def results(vehicle1, state1, vehicle2, state2, contact, prepared: Prepared, found: Impulse) -> ExchangeResult:
    """Every result of the exchange from its impulse (``impulse`` of the same inputs). Finite inputs far
    out of scale (a speed of 1e300 m/s), where |J|^2, |u|^2 or m |v|^2 overflows, get status
    ``INVALID_OVERFLOW`` rather than a silent NaN under "ok", and NaN in every number, as every invalid row:
    what was computed there (inf, NaN and finite values side by side) would read as results."""
    ok = prepared.status == OK
    vehicle1, state1, vehicle2, state2, contact = benign((vehicle1, state1, vehicle2, state2, contact), ok)
    status = jnp.where(ok & ~found.approaching, jnp.int32(SEPARATING), prepared.status)
    arr, rows = la.array, la.from_rows
    j, n, u = arr(found.j), arr(found.n), arr(found.u)
    result = derive(j, (found.size, found.ratio), n, contact.point, u, found.sliding, status,
                    (vehicle1, state1, rows(found.rot1), rows(found.a1), arr(found.r1)),
                    (vehicle2, state2, rows(found.rot2), rows(found.a2), arr(found.r2)))
    # the overflow check reads what every result reads anyway (J, u, the velocities and masses)
    fixed = is_fixed(vehicle2)  # an infinite mass has no finite kinetic energy to overflow: left out
    mass2 = jnp.where(fixed, jnp.zeros_like(vehicle2.mass), vehicle2.mass)
    scale = la.dot(j, j) + la.dot(u, u) + vehicle1.mass * la.dot(state1.velocity, state1.velocity) + \
        mass2 * la.dot(state2.velocity, state2.velocity)
    status = jnp.where(ok & ~jnp.isfinite(scale), jnp.int32(INVALID_OVERFLOW), result.contact.status)
    result = result._replace(contact=result.contact._replace(status=status))
    return mask_invalid(result, ok & (status != INVALID_OVERFLOW))
