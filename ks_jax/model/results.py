"""Everything the exchange derives from its impulse (docs/model.md, "Results"): delta-V, PDOF, crush,
EES, energy loss, the impulse's direction."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import linalg as la
from .types import ContactResult, ExchangeResult, VehicleResult


def pdof_degrees(force_body):
    """SAE J224 principal direction of force: atan2(F_y, -F_x) mod 360, degrees clockwise from
    the front (0 = a frontal force, pointing rearward; 90 = right side; 180 = rear)."""
    fx, fy, _ = la.vec(force_body)
    return la.degrees_0_360(la.safe_atan2(fy, -fx))


def clock(pdof):
    """Degrees in [0, 360) -> clock position 1..12 (12 = 0 deg, 3 = 90 deg), to the nearest hour; a half
    hour goes clockwise to the next (15 deg is 1 o'clock, 45 deg 2 o'clock, 345 deg 12 o'clock)."""
    hour = jnp.floor(pdof / 30.0 + 0.5)  # 0..12, and 0 is 12 o'clock
    return jnp.where(hour == 0, 12.0, hour)


# machine epsilons of a quantity's scale: how far a quantity that is 0 may be rounded off it (a unit
# direction's component in ``crush_depth``, the energy loss in ``ees_pair``, |T_c| - mu N_c in ``sliding``)
ROUNDING = 1e3


def crush_depth(point, direction, position, rot, vehicle):
    """Distance from ``point`` along ``direction`` (unit, global) until it leaves the
    vehicle's bounding box; 0 if the point is not inside the box (docs/model.md, "crush")."""
    p = la.matvec(rot, point - position, transpose=True)
    d = la.matvec(rot, direction, transpose=True)
    lo = jnp.stack([vehicle.cg_to_front - vehicle.length, -0.5 * vehicle.width, -vehicle.cg_height])
    hi = jnp.stack([vehicle.cg_to_front, 0.5 * vehicle.width, vehicle.height - vehicle.cg_height])
    inside = jnp.all((p >= lo) & (p <= hi))
    # A direction component within ROUNDING of 0 (a ray along that pair of faces, up to rounding) never
    # leaves through them. A threshold far above rounding rather than a test of d != 0: a component
    # that is 0 up to rounding (a yaw of 90 or 180 degrees) may be computed in two fused loops and
    # rounded differently in each, and a double-where whose test saw it nonzero and whose stand-in
    # saw it zero would give a finite wrong distance (``la.safe_sqrt`` says where that happened).
    # The stand-in, the threshold with d's sign, gives what d itself gives at the threshold.
    tol = ROUNDING * jnp.finfo(d.dtype).eps
    oblique = jnp.abs(d) > tol
    bound = jnp.where(d > 0, hi, lo)
    exit_dist = jnp.where(oblique, (bound - p) / jnp.where(oblique, d, jnp.copysign(tol, d)), jnp.inf)
    depth = jnp.min(exit_dist)
    return jnp.where(inside & jnp.isfinite(depth), depth, 0.0)


CRUSH_TOLERANCE = 1e-6  # relative to the sum of the two lengths: 10 um for two 5 m cars


def ees_pair(energy_loss, crush1, crush2, mass1, mass2, length_sum=1.0, energy_rounding=0.0):
    """Burg's EES (docs/model.md, "ees"): E_i = E C_i / (C_1 + C_2), EES_i = sqrt(2 E_i / m_i).

    NaN (undefined) when C_1 + C_2 = 0 or the energy loss is negative. "= 0" means below
    ``CRUSH_TOLERANCE * length_sum``: a centroid on a box face gives a crush of rounding size
    (1e-16 m), which must not hand the whole energy to one vehicle. "Negative" means below
    -``energy_rounding`` (J): an energy loss within it of 0 (an elastic stick, eps = 1) counts as 0, so
    that its EES is 0 however the program rounds it, not NaN in one program, 0 in another and 1e-7 m/s
    (the square root of a rounding error) in a third."""
    total = crush1 + crush2
    defined = (total > CRUSH_TOLERANCE * length_sum) & (energy_loss >= -energy_rounding)

    def one(c, m):
        e_i = la.safe_div(jnp.where(energy_loss > energy_rounding, energy_loss, 0.0) * c, total)
        return jnp.where(defined, la.safe_sqrt(2.0 * e_i / m), jnp.nan)

    return one(crush1, mass1), one(crush2, mass2)


def energy_loss_rounding(energy, j_mag, u, u_after):
    """The rounding of an exchange's energy loss E = -J.(u + u')/2 (``ees_pair``'s ``energy_rounding``), from |J| and
    the relative velocities at the centroid before and after (3,): the dot product's terms are at most
    |J| (|u| + |u'|) / 2. A tolerance, so without a derivative."""
    bound = 0.5 * j_mag * (la.safe_norm(u) + la.safe_norm(u_after))
    return jax.lax.stop_gradient(ROUNDING * jnp.finfo(energy.dtype).eps * bound)


def _vehicle(force, body, point, normal_into, j_mag):
    vehicle, state, rot, inv_inertia, r = body
    dv = force / vehicle.mass
    dw = la.matvec(inv_inertia, la.cross(r, force))
    v_after = state.velocity + dv
    w_after = state.angular_velocity + dw
    return VehicleResult(
        delta_v=dv,
        delta_v_magnitude=j_mag / vehicle.mass,
        delta_v_body=la.matvec(rot, dv, transpose=True),
        delta_yaw_rate=la.vec(dw)[2],
        velocity_after=v_after,
        speed_after=la.safe_norm(v_after),
        course_after=la.degrees_0_360(la.safe_atan2(*la.vec(v_after)[1::-1])),
        angular_velocity_after=w_after,
        yaw_rate_after=la.vec(w_after)[2],
        pdof=pdof_degrees(la.matvec(rot, force, transpose=True)),
        pdof_clock=jnp.zeros(()),  # filled below, from pdof
        crush=la.plain_zero(crush_depth(point, normal_into, state.position, rot, vehicle)),  # 0, not -0
        ees=jnp.zeros(()),  # filled below, needs both crushes
    )


def derive(j, factors, n, p, u, sliding, status, body1, body2) -> ExchangeResult:
    """Every result of the exchange from the impulse ``j`` on vehicle 1.

    factors = (size, ratio) of ``collision.Impulse``: J = size (n + T / N), ratio = |T| / N,
    from which |J| and |J_t| are computed (with their one-sided derivatives at J = 0 and J_t = 0).
    body_i = (vehicle, state, R, I^-1 global, r = P - x). The energy loss uses
    E = -J.(u + u')/2, which equals the kinetic-energy difference of both bodies (translation
    and rotation) and keeps its precision in float32.
    """
    size, ratio = factors
    # |J| = size sqrt(1 + ratio^2); as the norm of J, plus 0 whose derivative where size = 0 (eps = -1)
    # is the one-sided one (the norm's is 0 there): size sqrt(1 + ratio^2) itself makes a slower gradient
    j_mag = la.safe_norm(j) + jnp.where(size == 0, size * jax.lax.stop_gradient(jnp.sqrt(1.0 + ratio * ratio)), 0.0)
    v1 = _vehicle(j, body1, p, -n, j_mag)
    v2 = _vehicle(-j, body2, p, n, j_mag)
    r1, r2 = body1[4], body2[4]
    u_after = (v1.velocity_after + la.cross(v1.angular_velocity_after, r1)) - (
        v2.velocity_after + la.cross(v2.angular_velocity_after, r2)
    )
    energy = la.plain_zero(-0.5 * la.dot(j, u + u_after))  # J = 0 (separating): 0, not -0
    rounding = energy_loss_rounding(energy, j_mag, u, u_after)
    # against a fixed object vehicle 1 takes all of the energy (docs/model.md, "Fixed objects"): its crush
    # share is 1 and the object's 0, whatever the object's box holds
    fixed = body2[0].mass == jnp.inf
    crush1 = jnp.where(fixed, jnp.ones_like(v1.crush), v1.crush)
    crush2 = jnp.where(fixed, jnp.zeros_like(v2.crush), v2.crush)
    ees1, ees2 = ees_pair(energy, crush1, crush2, body1[0].mass, jnp.where(fixed, 1.0, body2[0].mass),
                          body1[0].length + body2[0].length, rounding)
    v1 = v1._replace(pdof_clock=clock(v1.pdof), ees=ees1)
    v2 = v2._replace(pdof_clock=clock(v2.pdof), ees=ees2)
    jn = la.dot(n, j)
    jx, jy, jz = la.vec(j)
    contact = ContactResult(
        point=p,
        normal=n,
        time=jnp.zeros_like(energy),
        impulse=j,
        impulse_magnitude=j_mag,
        impulse_normal=jn,
        impulse_tangential=size * ratio,
        impulse_azimuth=la.degrees_0_360(la.safe_atan2(jy, jx)),
        impulse_elevation=jnp.degrees(la.safe_atan2(jz, la.safe_sqrt(jx * jx + jy * jy))),
        sliding=sliding,
        closing_velocity=u,
        separation_velocity=u_after,
        energy_loss=energy,
        status=status,
    )
    return ExchangeResult(contact=contact, vehicles=(v1, v2))


def mask_invalid(result: ExchangeResult, ok) -> ExchangeResult:
    """NaN in every numeric result, False in ``sliding``, of a row with invalid inputs; the
    status code keeps the reason."""

    def mask(x):
        if x.dtype == jnp.bool_:
            return x & ok
        if jnp.issubdtype(x.dtype, jnp.integer):
            return x
        return jnp.where(ok, x, jnp.nan)

    return jax.tree_util.tree_map(mask, result)
