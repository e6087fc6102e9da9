"""The automatic stage (docs/model.md, "Automatic contact"): free motion to the first touch
(``search``), on by the penetration time, the centroid and normal of the overlap there
(``overlap``; ``pole`` for a pole), and the exchange at that contact (``model.collision``).

- ``time`` (``contact.time``) reports the first-contact time t_i, as the manual's "timing"
  panel does; the exchange itself happens at t_i + penetration_time. For an explicit contact
  (``ks_jax.exchange``) time is 0: the exchange is at the case state.
- Touched, then parted: where the footprints no longer overlap at t_i + penetration_time (a
  glancing touch shorter than the penetration time), there is no overlap to put the centroid in:
  status INVALID_PARTED ("penetration_time is too long"), NaN results, as for other bad input.
- Never touching within the horizon: status "no_contact" and no NaN anywhere: zero impulse,
  zero delta-V, velocity_after = velocity, crush and EES 0, ``time`` = HORIZON, point the
  midpoint of the CGs and normal the horizontal direction from CG 2 to CG 1, both at t = 0.
- Inputs that break a rule (``checks.input_status``) give that status and NaN
  results, exactly as ``ks_jax.exchange`` does; the geometry of such a row runs on harmless
  stand-in values so that neither it nor its gradient can produce NaN elsewhere.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .. import linalg as la
from ..checks import benign, input_status, is_fixed
from ..collision import exchange
from ..results import mask_invalid
from ..types import INVALID_PARTED, NO_CONTACT, OK, Contact, ExchangeResult, State, Vehicle
from .geometry import (
    advance,
    edge_normals,
    footprint,
    length_tolerance,
    penetrations,
    reach,
    separation,
    vertical_middle,
)
from .overlap import Contact2D, contact_geometry, growing_overlap, tilt
from .pole import disc_contact, disc_gap
from .search import HORIZON, first_contact


class AutoContact(NamedTuple):
    """Everything automatic contact decides before the exchange (for plots and checks):
    time t_i () s, found () bool, states at the exchange instant, the contact used, the
    overlap geometry (``Contact2D``) at that instant, parted () bool: the footprints touched
    but are apart again at the exchange instant (a penetration_time longer than the touch),
    at_touch () bool: the exchange is at the touch itself (penetration_time 0, point and normal
    automatic), and touch_crush (2,) m: there, the crushes (0, with their derivative in
    penetration_time, which ``exchange_at_contact`` puts in place of the exchange's)."""

    time: jnp.ndarray
    found: jnp.ndarray
    state1: State
    state2: State
    contact: Contact
    geometry: Contact2D
    parted: jnp.ndarray
    at_touch: jnp.ndarray
    touch_crush: jnp.ndarray


def automatic_contact(vehicle1, state1, vehicle2, state2, contact, normal_pitch, *, auto_point, auto_normal,
                      pole=False):
    """Free motion to t_i + penetration_time and the contact there (docs/model.md, "Automatic contact").

    ``contact.point`` (3,) m (global, at the exchange instant) is used where ``auto_point`` is
    False, ``contact.normal`` (3,) where ``auto_normal`` is False; ``normal_pitch`` () rad tilts
    the automatic normal. Returns an ``AutoContact``; where ``found`` is False the contact is a
    harmless separating one at t = 0 (see the module docstring)."""
    # the geometry about the CGs' midpoint: its tolerances (~1e-12 m) are below the rounding of
    # coordinates of 1e4 m and more, where the same scene gave another centroid and normal
    origin = (0.5 * (state1.position + state2.position)).at[2].set(0.0)
    near1, near2 = (s._replace(position=s.position - origin) for s in (state1, state2))
    gap = disc_gap if pole else separation
    t_i, found = first_contact(vehicle1, near1, vehicle2, near2, disc_gap if pole else None)
    t_x = jnp.where(found, t_i + contact.penetration_time, 0.0)
    a1, a2 = advance(state1, t_x), advance(state2, t_x)
    if pole:  # a disc: no growing-overlap correction of the touch's derivative in penetration_time
        geo = _pole_geometry(vehicle1, advance(near1, t_x), vehicle2, advance(near2, t_x), la.safe_norm(origin),
                             advance(near1, t_i), advance(near2, t_i))
        growth = jnp.zeros(4, t_x.dtype)
    else:
        # the face that touched first: where the faces facing each other decide the normal, theirs
        t1, t2 = advance(near1, t_i), advance(near2, t_i)
        touched = jnp.argmin(penetrations(footprint(vehicle1, t1.position[:2], t1.yaw),
                                          footprint(vehicle2, t2.position[:2], t2.yaw),
                                          edge_normals(t1.yaw, t2.yaw))) % 4
        geo = contact_geometry(vehicle1, advance(near1, t_x), vehicle2, advance(near2, t_x), la.safe_norm(origin),
                               touched)
        growth = growing_overlap(contact.penetration_time, (vehicle1, near1, vehicle2, near2, t_i, t_x,
                                                             la.safe_norm(origin), normal_pitch))
    shift = jnp.where(geo.solid, 0.0, jnp.concatenate([growth[:2], jnp.zeros(1, growth.dtype)]))
    geo = geo._replace(point=geo.point + shift + origin, polygon=geo.polygon + origin[:2],
                       crossings=geo.crossings + origin[:2])
    point = jnp.where(auto_point, geo.point, contact.point)
    normal = jnp.where(auto_normal, tilt(geo.normal, normal_pitch), contact.normal)

    # never touching: an exchange that cannot happen (u.n >= 0), at the CGs' midpoint, t = 0
    mid = 0.5 * (state1.position + state2.position)
    u = (state1.velocity + la.cross(state1.angular_velocity, mid - state1.position)) - (
        state2.velocity + la.cross(state2.angular_velocity, mid - state2.position))
    u_len = la.safe_norm(u)
    x_axis = jnp.zeros(3, u.dtype).at[0].set(1.0)
    n_sep = jnp.where(u_len > 0, u / jnp.where(u_len > 0, u_len, 1.0), x_axis)
    contact = contact._replace(point=jnp.where(found, point, mid), normal=jnp.where(found, normal, n_sep))
    gap = gap(vehicle1, near1, vehicle2, near2, t_x)  # <= 0 at t_i itself, to rounding
    gap_tol = 1e3 * jnp.finfo(gap.dtype).eps * (reach(vehicle1) + jnp.where(is_fixed(vehicle2), 0.0, reach(vehicle2))
                                                + la.safe_norm(origin))
    parted = found & (contact.penetration_time > 0) & (gap > gap_tol)
    at_touch = found & ~geo.solid & (contact.penetration_time == 0) & auto_point & auto_normal
    return AutoContact(jnp.where(found, t_i, HORIZON), found, a1, a2, contact, geo, parted, at_touch, growth[2:])


def _pole_geometry(vehicle1, state1, vehicle2, state2, coordinates, touch1, touch2) -> Contact2D:
    """``contact_geometry`` where vehicle 2 is a pole (``pole.disc_contact``), with the same length
    tolerance; no outline crossings. ``touch1``, ``touch2``: the states at the first touch."""
    corners1 = footprint(vehicle1, state1.position[:2], state1.yaw)
    len_tol = length_tolerance(vehicle1, vehicle2, state1.position.dtype, coordinates)
    xy, n, poly, count, area, solid = disc_contact(vehicle1, state1, state2.position[:2], 0.5 * vehicle2.width,
                                                   corners1, len_tol, touch1, touch2.position[:2])
    z = vertical_middle(vehicle1, state1, vehicle2, state2)
    zero = jnp.zeros((), xy.dtype)
    no = jnp.zeros((), bool)  # no outline crossings: the plane is the tangent at the centroid
    flags = {k: no for k in Contact2D._fields if k in ("crossing_ok", "facing")}
    return Contact2D(point=jnp.stack([xy[0], xy[1], z]), normal=jnp.stack([n[0], n[1], zero]), polygon=poly,
                     count=count, area=area, crossings=jnp.zeros((2, 2), xy.dtype), solid=solid, **flags)


def automatic_exchange(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
                       normal_pitch, *, auto_point: bool, auto_normal: bool, smoothing=0.0,
                       pole: bool = False) -> ExchangeResult:
    """The KS exchange at the automatic contact (docs/model.md).

    Vehicles (mass kg, inertia kg m^2, box m) and states (position m, velocity m/s, yaw rad,
    angular_velocity rad/s) are those of the case start; ``contact`` as for ``exchange``
    (restitution, friction, penetration_time s; point (3,) m and normal (3,) where not
    automatic); ``normal_pitch`` () rad. ``auto_point``/``auto_normal`` are static bools (they
    may also be traced bool arrays: the choice is a select, so one compiled program can serve
    rows with different user overrides).
    Returns ``ks_jax.exchange``'s result at t_i + penetration_time with ``contact.time`` = t_i
    (s); status "no_contact" and no NaN when the footprints do not touch within HORIZON.
    Pure and unbatched; works under ``jax.jit``, ``jax.vmap`` and ``jax.grad``.

    It is ``exchange_at_contact(automatic_stage(input_status(...)))``: the split that a batched
    caller may compute apart (``ks_jax.batch``).
    """
    args = (vehicle1, state1, vehicle2, state2, contact)
    status = input_status(*args)
    auto = automatic_stage(*args, normal_pitch, status, auto_point=auto_point, auto_normal=auto_normal, pole=pole)
    return exchange_at_contact(*args, status, auto, smoothing)


def automatic_stage(vehicle1, state1, vehicle2, state2, contact, normal_pitch, status, *, auto_point,
                    auto_normal, pole=False) -> AutoContact:
    """``automatic_contact`` of a row whose ``input_status`` is ``status`` (() int32), run on harmless
    stand-in inputs where that is not OK. Its ``geometry`` is None (the exchange does not need it)."""
    ok = status == OK
    stand_ins = benign((vehicle1, state1, vehicle2, state2, contact), ok)
    normal_pitch = jnp.where(ok & jnp.isfinite(normal_pitch), normal_pitch, 0.0)
    auto = automatic_contact(*stand_ins, normal_pitch, auto_point=auto_point, auto_normal=auto_normal, pole=pole)
    return auto._replace(geometry=None)


def exchange_at_contact(vehicle1, state1, vehicle2, state2, contact, status, auto: AutoContact,
                        smoothing=0.0) -> ExchangeResult:
    """The exchange at ``auto`` (``automatic_stage`` of the same inputs and ``status``), with the
    results of a row that never touches set as the module docstring says."""
    ok = status == OK
    pick = lambda new, old: jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, old)  # noqa: E731
    result = exchange(vehicle1, pick(auto.state1, state1), vehicle2, pick(auto.state2, state2),
                      pick(auto.contact, contact), smoothing)

    none = ok & ~auto.found
    c = result.contact
    towards1 = jnp.where(ok, state1.position - state2.position, 0.0)
    towards1 = towards1.at[2].set(0.0)
    length = la.safe_norm(towards1)
    x_axis = jnp.zeros(3, towards1.dtype).at[0].set(1.0)
    n_none = jnp.where(length > 0, towards1 / jnp.where(length > 0, length, 1.0), x_axis)
    c = c._replace(
        time=jnp.where(ok, auto.time, c.time),
        normal=jnp.where(none, n_none, c.normal),
        status=jnp.where(none, jnp.int32(NO_CONTACT), c.status),
    )
    touch = ok & auto.at_touch
    vehicles = tuple(v._replace(crush=jnp.where(none, 0.0, jnp.where(touch, auto.touch_crush[k], v.crush)),
                                ees=jnp.where(none, 0.0, v.ees))
                     for k, v in enumerate(result.vehicles))
    parted = ok & auto.found & auto.parted
    result = mask_invalid(ExchangeResult(c, vehicles), ~parted)
    return result._replace(contact=result.contact._replace(
        status=jnp.where(parted, jnp.int32(INVALID_PARTED), result.contact.status)))
