"""The friction cone of the Kudlich-Slibar exchange (docs/model.md, "The impulse exchange", step 5)."""

from __future__ import annotations

import jax.numpy as jnp

from . import linalg as la
from .results import ROUNDING


FRICTION_CAP = (1e10, 1e100)  # float32, float64


def friction_cone(j_stick, n, friction, smoothing=0.0):
    """The direction d of the impulse, limited by the friction cone: J = N d with n.d = 1.

    j_stick: (3,) the common-velocity (stick) impulse J_c = -K^-1 u; n: (3,) the unit normal (from
    vehicle 2 into vehicle 1); friction: () mu >= 0; smoothing: () tau in [0, 1), 0 for the exact cone.
    Returns (d (3,), ratio (), sliding ()): d = n + T / N, ratio = |T| / N (the tangential impulse per
    unit of normal impulse) and sliding = |T_c| > mu N_c (beyond rounding).

    Derivation. Split the stick impulse into N_c = n.J_c and T_c = J_c - N_c n. The model keeps the
    direction of T_c and limits its ratio to the normal part:

        s* = min(1, mu N_c / |T_c|),   d(s*) = n + s* T_c / N_c,

    so s* = 1 is the stick impulse (it brings all of the relative velocity at P to zero) and s* < 1
    slides on the cone, |T| = mu N. Where N_c <= 0 (the stick impulse would pull) the contact slides
    with d = n + mu T_c / |T_c|. Both cases are one formula, with no division by N_c or |T_c|:

        d = n + mu T_c / M,   M = max(mu max(N_c, 0), |T_c|)

    (M = mu N_c gives d = J_c / N_c, the stick direction; M = |T_c| gives n + mu t, sliding.)

    Smooth cone (tau > 0): the max becomes the p-norm M_tau = (a^p + b^p)^(1/p), p = 1/tau, which is
    the smooth minimum s*_tau = (1 + (mu N_c / |T_c|)^-p)^(-1/p) of s*. It never leaves the cone
    (M_tau >= M, so |T| <= mu N), and M <= M_tau <= 2^tau M: s* moves by at most a factor 2^-tau, so
    |J_tau - J_0| <= C tau |J_0| with C = ln 2 s |dJ/ds| / |J|. C depends on mu and K and has no bound
    of its own: it grows with n.K.n / n.K.d(1), and is largest near grazing (u.n small against |u|).
    J_tau is continuously differentiable wherever u.n < 0, and every derivative is finite at the kinks
    (head-on, T_c = 0; mu = 0; exactly on the cone).
    """
    n_c = la.dot(n, j_stick)
    t_c = j_stick - n_c * n
    t_norm = la.safe_norm(t_c)
    # a friction above FRICTION_CAP sticks wherever the stick impulse pushes (unless |T_c| > cap N_c), as any
    # friction that large does: capped, mu N_c cannot overflow and make M infinite (which would drop the
    # friction altogether: d = n)
    dtype = jnp.result_type(friction, n_c)
    friction = jnp.minimum(friction, jnp.asarray(FRICTION_CAP[jnp.finfo(dtype).bits > 32], dtype))
    a = friction * jnp.maximum(n_c, 0.0)
    m = cone_scale(a, t_norm, smoothing)
    f = la.safe_div(friction, m)
    # sliding needs |T_c| above mu N_c by more than rounding: where the two are equal (an inline crash
    # at mu = 0, |T_c| = mu N_c = 0) the flag would otherwise be decided by how a program rounds them
    rounding = ROUNDING * jnp.finfo(t_norm.dtype).eps * (jnp.abs(n_c) + t_norm)
    return n + f * t_c, f * t_norm, t_norm > a + rounding


def cone_scale(a, b, smoothing):
    """M = max(a, b) (smoothing 0) or the p-norm (a^p + b^p)^(1/p), p = 1/smoothing, for a, b >= 0,
    with finite gradients everywhere, a = b and a = b = 0 included. A Python number 0 gives the exact
    max with no smoothing arithmetic at all."""
    hard = jnp.maximum(a, b)
    if isinstance(smoothing, (int, float)) and smoothing == 0:
        return hard
    tau = jnp.asarray(smoothing)
    p = 1.0 / jnp.where(tau > 0, tau, 1.0)
    hi, lo = hard, jnp.minimum(a, b)
    ratio = la.safe_div(lo, hi)
    smooth = hi * jnp.exp(jnp.log1p(ratio**p) / p)
    return jnp.where(tau > 0, smooth, hard)
