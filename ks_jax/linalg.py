"""Closed-form 3-vector and 3x3 algebra, safe to differentiate everywhere.

Written out component by component so that, batched under vmap, XLA fuses it into
elementwise loops instead of calling a batched LAPACK routine per row. ``safe_*`` use the
double-where pattern: the singular point is never passed to sqrt, division or arctan2.
"""

from __future__ import annotations

import jax.numpy as jnp


def cross(a, b):
    return jnp.stack(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]], -1
    )


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def matvec(m, v):
    return jnp.stack([dot(m[i], v) for i in range(3)], -1)


def matmul(a, b):
    bt = b.T
    return jnp.stack([jnp.stack([dot(a[i], bt[j]) for j in range(3)]) for i in range(3)])


def det3(m):
    return (
        m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
        - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
        + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])
    )


def adjugate3(m):
    """Adjugate (transpose of the cofactor matrix): m @ adj(m) = det(m) Id."""
    c = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(3):
            r = [k for k in range(3) if k != i]
            s = [k for k in range(3) if k != j]
            minor = m[r[0], s[0]] * m[r[1], s[1]] - m[r[0], s[1]] * m[r[1], s[0]]
            c[j][i] = minor if (i + j) % 2 == 0 else -minor
    return jnp.stack([jnp.stack(row) for row in c])


def trig(yaw, pitch, roll):
    """(cos yaw, sin yaw, cos pitch, sin pitch, cos roll, sin roll): the six transcendentals of
    ``rotation``. A batched caller may compute them once in their own jitted call: XLA's CPU
    loop fusion otherwise re-evaluates them (scalar libm calls) in every loop that reads R."""
    return jnp.cos(yaw), jnp.sin(yaw), jnp.cos(pitch), jnp.sin(pitch), jnp.cos(roll), jnp.sin(roll)


def rotation_from_trig(cz, sz, cy, sy, cx, sx):
    """R from ``trig``'s six values."""
    return jnp.stack(
        [
            jnp.stack([cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx]),
            jnp.stack([sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx]),
            jnp.stack([-sy, cy * sx, cy * cx]),
        ]
    )


def rotation(yaw, pitch, roll):
    """R = Rz(yaw) Ry(pitch) Rx(roll): body (ISO 8855) -> global."""
    return rotation_from_trig(*trig(yaw, pitch, roll))


def safe_norm(v):
    """|v|, with gradient 0 (not NaN) at v = 0."""
    sq = dot(v, v) if v.shape[-1] == 3 else jnp.sum(v * v, -1)
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def safe_sqrt(x):
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def safe_div(a, b, fallback=0.0):
    """a / b where b != 0, else ``fallback``, with finite gradients."""
    nz = b != 0
    return jnp.where(nz, a / jnp.where(nz, b, 1.0), fallback)


def safe_atan2(y, x):
    """atan2 with 0 (value and gradient) at the origin."""
    zero = (x == 0) & (y == 0)
    return jnp.where(zero, 0.0, jnp.arctan2(y, jnp.where(zero, 1.0, x)))


def degrees_0_360(rad):
    """Radians -> degrees in [0, 360)."""
    d = jnp.mod(jnp.degrees(rad), 360.0)
    return jnp.where((d >= 360.0) | (d == 0.0), jnp.where(d == 0.0, 0.0, d - 360.0), d)
