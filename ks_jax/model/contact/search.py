"""When automatic contact's footprints first touch (docs/model.md, "Automatic contact").

Pure and unbatched, built from fixed-size arrays (a footprint is (4, 2)), so it works under
``jax.jit``, ``jax.vmap`` and ``jax.grad``.

- Footprints and free motion as ``geometry`` defines them; s(t) is ``geometry.separation``, or the
  ``gap`` that ``first_contact`` is given (a pole's: ``pole.disc_gap``).
- First contact is searched in [0, HORIZON] = [0, 10] s. Where neither vehicle rotates it is
  exact (closed form: the separating-axis test swept along the relative translation is a set
  of 8 linear inequalities in t). Where one rotates, the search keeps to the reach window
  (``reach_window``): the times at which the circles about the CGs that hold each footprint
  at any yaw overlap, which the CGs' straight paths give in closed form; outside it the
  footprints cannot touch, and vehicles that never come within reach are "no_contact"
  without a search. Inside it, the separating-axis function s(t) = max over the 4 edge
  normals of the gap between the projections (> 0 apart, <= 0 touching) is advanced
  conservatively: s(t) is at most the distance between the footprints, which shrinks at most
  at |v_1 - v_2| + |w_1| R_1 + |w_2| R_2, so no touch comes before t + s(t) / that bound.
  Each step is that long but at least (window length) / SCAN_STEPS: 5 ms at most, and about
  0.2 ms where two cars pass at 20 m/s. Only a graze shorter than that least step, and only
  once the footprints are within a step's travel of each other, can be missed. The step that
  lands on s <= 0 brackets the touch, refined by regula falsi (Illinois) aimed a hair inside
  the touch so that it lands on the touching side, with a bisection wherever a step fails to
  halve the bracket: it ends at a time where the footprints touch, overlapping by at most
  16 machine epsilons of R_1 + R_2 (``_refine``; REFINE_STEPS caps it).
- Gradients of t_i are those of the touching condition s(t_i, theta) = 0 (implicit function
  theorem, applied as one Newton step from a stop_gradient root), so they see speeds,
  headings, positions and yaw rates in both cases; 0 when the vehicles overlap at t = 0.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .. import linalg as la
from ..checks import is_fixed
from .geometry import edge_normals, footprint_at, penetrations, reach, separation

HORIZON = 10.0  # s, search horizon for the first contact
SCAN_STEPS = 2000  # the least step where a vehicle rotates: the reach window / SCAN_STEPS (<= 5 ms)
REFINE_STEPS = 128  # a cap on ``_refine``: a bracket of 10 s takes ~53 halvings to a few ulps, at most 2 steps each


def _translation_contact(vehicle1, state1, vehicle2, state2):
    """Closed form where neither vehicle rotates: (t_i, found). All 8 penetrations are linear
    in t, f_k(t) = f_k + g_k t, and the footprints touch iff all are >= 0."""
    c1 = footprint_at(vehicle1, state1, 0.0)
    c2 = footprint_at(vehicle2, state2, 0.0)
    axes = edge_normals(state1.yaw, state2.yaw)
    f = penetrations(c1, c2, axes)
    rate = la.mm(axes, state1.velocity[:2] - state2.velocity[:2])  # d/dt of vehicle 1's projections
    g = jnp.concatenate([-rate, rate])
    root = la.safe_div(-f, g)
    big = jnp.asarray(1e30, f.dtype)
    lo = jnp.maximum(0.0, jnp.max(jnp.where(g > 0, root, -big)))
    hi = jnp.min(jnp.where(g < 0, root, big))
    feasible = jnp.all((g != 0) | (f >= 0))
    found = feasible & (lo <= hi) & (lo <= HORIZON)
    return lo, found


def reach_window(vehicle1, state1, vehicle2, state2):
    """(t_a, t_b, within): the times t >= 0 at which the footprints' circles of reach (``geometry.reach``
    about each CG, moving with the CG) overlap, whatever the vehicles' yaw rates: the footprints
    can touch only then. ``within`` is False where the circles never overlap; t_b is inf where
    they overlap for ever (equal velocities). The circles are 0.1% larger than they need be, so
    that rounding cannot shut out a touch."""
    r = 1.001 * (reach(vehicle1) + reach(vehicle2))
    d = state1.position[:2] - state2.position[:2]
    dv = state1.velocity[:2] - state2.velocity[:2]
    a, b, c = jnp.sum(dv * dv), jnp.sum(d * dv), jnp.sum(d * d) - r * r
    # |d + dv t|^2 <= r^2  <=>  a t^2 + 2 b t + c <= 0; the roots in forms free of cancellation
    disc = b * b - a * c
    sq = jnp.sqrt(jnp.maximum(disc, 0.0))
    inside = c <= 0
    within = inside | ((b < 0) & (disc >= 0))
    t_a = jnp.where(inside, 0.0, la.safe_div(c, sq - b))
    inf = jnp.asarray(jnp.inf, d.dtype)
    t_b = jnp.where(b < 0, la.safe_div(sq - b, a, inf), la.safe_div(-c, b + sq, inf))
    t_b = jnp.where(a > 0, t_b, inf)
    return t_a, jnp.maximum(t_a, t_b), within


def _scan_contact(vehicle1, state1, vehicle2, state2, skip, gap=None):
    """Conservative advancement over the part of [0, HORIZON] inside the reach window, then
    ``_refine``: (t_i, found). Rows where ``skip`` is True are not searched (found False).

    s(t) never exceeds the distance between the footprints (a gap between projections on a unit
    axis is at most the distance), and that distance shrinks at most at the closing bound
    |v_1 - v_2| + |w_1| R_1 + |w_2| R_2 (R_i the reach): no touch can come before
    t + s(t) / bound. Each step is that long, but at least (window length) / SCAN_STEPS, and the
    first step that lands on s <= 0 brackets the touch for ``_refine``."""
    t_a, t_b, within = reach_window(vehicle1, state1, vehicle2, state2)
    t_end = jnp.clip(t_b, t_a, HORIZON)
    within = within & (t_a <= HORIZON) & ~skip
    h = (t_end - t_a) / SCAN_STEPS
    dv = state1.velocity[:2] - state2.velocity[:2]
    bound = 1.001 * (la.safe_norm(dv) + jnp.abs(state1.angular_velocity[2]) * reach(vehicle1)
                     + jnp.abs(state2.angular_velocity[2]) * reach(vehicle2))
    gap = separation if gap is None else gap  # a pole's: ``pole.disc_gap``
    sep = lambda t: gap(vehicle1, state1, vehicle2, state2, t)  # noqa: E731

    def cond(carry):
        return ~carry[-1]

    def body(carry):
        k, t, s, _, _, _, _ = carry
        t_next = jnp.minimum(t + jnp.maximum(la.safe_div(s, bound, h), h), t_end)
        s_next = sep(t_next)
        found = s_next <= 0
        return k + 1, t_next, s_next, t, s, found, found | (t_next >= t_end) | (k + 1 >= SCAN_STEPS + 2)

    s_a = sep(t_a)
    at_start = within & (s_a <= 0)
    init = (jnp.int32(0), t_a, s_a, t_a, s_a, at_start, ~within | at_start)
    _, t_hit, s_hit, t_before, s_before, found, _ = jax.lax.while_loop(cond, body, init)
    tol = 16 * jnp.finfo(t_hit.dtype).eps * (reach(vehicle1) + jnp.where(is_fixed(vehicle2), 0.0, reach(vehicle2)))
    t_root = _refine(sep, t_before, t_hit, s_before, s_hit, tol, found & ~at_start)
    return jnp.where(at_start, t_a, t_root), found


def _refine(sep, lo, hi, s_lo, s_hi, tol, active):
    """A time in [lo, hi] where sep <= 0 and sep >= -tol, given sep(lo) > 0 >= sep(hi): hi itself
    where ``active`` is False or sep(hi) >= -tol already.

    Regula falsi aimed at sep = -tol / 2 (so that where sep is straight, one step lands inside
    the tolerance, on the touching side), with the Illinois rule (the end kept twice in a row has
    its value halved, so that neither end stalls) and a bisection after any step that did not
    halve the bracket: never slower than about two bisections a halving, and under vmap a while
    loop, so rows with nothing to refine skip it. It also ends where the bracket is a few ulps
    wide, or after REFINE_STEPS steps."""
    eps = jnp.finfo(lo.dtype).eps

    def cond(carry):
        k, lo, hi, _, s_hi, _, _ = carry
        return active & (s_hi < -tol) & (hi - lo > 4 * eps * jnp.abs(hi)) & (k < REFINE_STEPS)

    def body(carry):
        k, lo, hi, s_lo, s_hi, kept, last_width = carry
        width = hi - lo
        t_secant = lo + (s_lo + 0.5 * tol) * la.safe_div(width, s_lo - s_hi)
        bisect = (width > 0.5 * last_width) | ~(t_secant > lo) | ~(t_secant < hi)
        t = jnp.where(bisect, 0.5 * (lo + hi), t_secant)
        s = sep(t)
        touching = s <= 0
        s_lo = jnp.where(touching, jnp.where(kept == 1, 0.5 * s_lo, s_lo), s)
        s_hi = jnp.where(touching, s, jnp.where(kept == -1, 0.5 * s_hi, s_hi))
        kept = jnp.where(touching, jnp.int32(1), jnp.int32(-1))  # 1: lo kept, -1: hi kept
        last_width = jnp.where(bisect, jnp.inf, width)
        return k + 1, jnp.where(touching, lo, t), jnp.where(touching, t, hi), s_lo, s_hi, kept, last_width

    inf = jnp.asarray(jnp.inf, lo.dtype)
    init = (jnp.int32(0), lo, hi, s_lo, s_hi, jnp.int32(0), inf)
    return jax.lax.while_loop(cond, body, init)[2]


def first_contact(vehicle1, state1, vehicle2, state2, gap=None):
    """First time t_i >= 0 (s) at which the footprints touch under free motion, and whether
    they were found to: ((), bool ()). Differentiable through the touching condition. ``gap``: the
    separation function of vehicle 2's footprint where it is not a box (a pole's ``pole.disc_gap``), which
    is searched as the footprints of turning vehicles are."""
    params = jax.lax.stop_gradient((vehicle1, state1, vehicle2, state2))
    translating = (params[1].angular_velocity[2] == 0) & (params[3].angular_velocity[2] == 0)
    if gap is not None:
        translating = jnp.zeros_like(translating)  # the closed form is the boxes'
    t_lin, found_lin = _translation_contact(*params)
    t_rot, found_rot = _scan_contact(*params, translating, gap)
    t0 = jnp.where(translating, t_lin, t_rot)
    found = jnp.where(translating, found_lin, found_rot)
    t0 = jnp.where(found, t0, 0.0)

    # implicit differentiation: t = t0 - (s(t0, theta) - s(t0, theta0)) / s_t(t0, theta0)
    gap = separation if gap is None else gap
    s_theta, s_t = jax.jvp(lambda t: gap(vehicle1, state1, vehicle2, state2, t), (t0,), (jnp.ones_like(t0),))
    correction = la.safe_div(s_theta - jax.lax.stop_gradient(s_theta), jax.lax.stop_gradient(s_t))
    t = t0 - jnp.where(found & (t0 > 0), correction, 0.0)
    return t, found
