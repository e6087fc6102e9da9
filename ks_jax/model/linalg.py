"""Closed-form 3-vector and 3x3 algebra, safe to differentiate everywhere.

Written out component by component so that, batched under vmap, XLA fuses it into
elementwise loops instead of calling a batched LAPACK routine per row. ``safe_*`` use the
double-where pattern: the singular point is never passed to sqrt, division or arctan2.

Components. Vectors and matrices are read with ``vec``/``mat`` (one ``unstack``), never as
``v[i]``, and the functions here accept arrays or tuples of components (``*_c`` return
components, the others arrays). Reverse mode is why: the cotangent of each ``v[i]`` is a ``pad``
into a zero array, and the pads are then added up; batched, those pads and adds were most of
the backward pass. The transpose of one ``unstack`` is one ``stack``.

Trigonometry, one rule for the whole model: in its programs (jit-compiled and vmapped, the angle an
array), sin and cos are ``sincos`` (one angle) or ``trig`` (the three angles of a rotation, for
``rotation``/``rotation_c``), and atan2 is ``safe_atan2``; never ``jnp.sin``, ``jnp.cos`` or
``jnp.arctan2`` (nor ``jnp.mod``, see ``degrees_0_360``). XLA's CPU backend evaluates those by a scalar libm
call per value, in loops that are not vectorized; the polynomial forms here vectorize, are within 1-4 ulp of
NumPy in float64 (the tests hold them to it), and differentiate everywhere (``safe_atan2`` is 0, with
gradient 0, at the origin). An angle known when the program is traced (a constant) is evaluated once with
NumPy or ``math``, as is Python-side arithmetic on plain floats (reading case files, writing reports).
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax


if hasattr(lax, "unstack"):
    def _unstack(x):
        return tuple(lax.unstack(x))
else:  # older jax: indexing (same values; the backward pass is slower)
    def _unstack(x):
        return tuple(x[i] for i in range(x.shape[0]))


def vec(v):
    """The three components of a 3-vector (a tuple is returned as is; an array is unstacked
    once, whose transpose is one stack rather than a pad per component)."""
    if isinstance(v, (tuple, list)):
        return tuple(v)
    return _unstack(jnp.asarray(v))


def mat(m):
    """The nine entries of a 3x3 matrix, as three rows of components (see ``vec``)."""
    if isinstance(m, (tuple, list)):
        return tuple(vec(row) for row in m)
    return tuple(vec(row) for row in _unstack(jnp.asarray(m)))


def array(v):
    """A (3,) array from components."""
    return jnp.stack(vec(v), -1)


def from_rows(rows):
    """A (3, 3) array from three rows of three components."""
    return jnp.stack([jnp.stack(vec(row)) for row in rows])


def transpose_c(m):
    return tuple(zip(*mat(m)))


def dot(a, b):
    a, b = vec(a), vec(b)
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross_c(a, b):
    a, b = vec(a), vec(b)
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def cross(a, b):
    return array(cross_c(a, b))


def mm(a, b):
    """``a @ b`` at the full precision of its dtype on every platform. An accelerator's default for a float32
    product may be TF32 (a 10-bit mantissa: relative errors to 5e-4, millimetres on a car's corners, and a one-hot
    selection that rounds what it selects); the CPU's is already full, so there nothing changes."""
    return jnp.matmul(a, b, precision=jax.lax.Precision.HIGHEST)


def _matvec_c(m, v, transpose=False):
    """m v, or m^T v with ``transpose``."""
    rows = transpose_c(m) if transpose else mat(m)
    v = vec(v)
    return tuple(dot(row, v) for row in rows)


def matvec(m, v, transpose=False):
    return array(_matvec_c(m, v, transpose))


def matmul_c(a, b, transpose_b=False):
    """a b, or a b^T with ``transpose_b``."""
    cols = mat(b) if transpose_b else transpose_c(b)
    return tuple(tuple(dot(row, col) for col in cols) for row in mat(a))


def det3(m):
    m = mat(m)
    return (
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    )


def adjugate_c(m):
    """Adjugate (transpose of the cofactor matrix): m @ adj(m) = det(m) Id."""
    m = mat(m)
    c = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(3):
            r = [k for k in range(3) if k != i]
            s = [k for k in range(3) if k != j]
            minor = m[r[0]][s[0]] * m[r[1]][s[1]] - m[r[0]][s[1]] * m[r[1]][s[0]]
            c[j][i] = minor if (i + j) % 2 == 0 else -minor
    return tuple(tuple(row) for row in c)


def adjugate3(m):
    return from_rows(adjugate_c(m))


def materialize(*xs, everywhere=False):
    """``xs`` (arrays of one shape and float dtype) unchanged, computed in a loop of their own
    and stored, batched under vmap, in a program compiled for a CPU.

    XLA's CPU fusion copies an elementwise producer into every loop that reads it: the six
    sines/cosines of a rotation (``sincos``, about 40 operations per angle) would be evaluated
    again in each of the dozens of loops that read them, several of which (XLA's concatenate
    loops) are not vectorized. ``lax.optimization_barrier`` is dropped before fusion on CPU, and a
    max-reduce over copies is rewritten into an elementwise op; a bitwise-or reduction of the
    bits with zeros is kept as a reduction, which is not copied into elementwise consumers.
    The values are exact (NaN and signed zeros kept). Not differentiable: differentiate around it (``trig`` has its
    own derivative). In a program compiled for another platform ``xs`` are returned as they are
    (``lax.platform_dependent``, resolved when the program is lowered: the choice is the platform's, not the
    caller's): a GPU's fusions do not copy producers that way, and there the reduction was a kernel of its own
    that stored and read back every value (over a third of the exchange's time). ``everywhere``: stored on every
    platform (a value that every later kernel reads, which a GPU's fusion would otherwise recompute in each)."""
    xs = tuple(jnp.broadcast_arrays(*xs))
    if everywhere:
        return _stored(*xs)
    return tuple(lax.platform_dependent(*xs, cpu=_stored, default=lambda *values: tuple(values)))


def _stored(*xs):
    """``xs`` through a bitwise-or reduction with zeros (``materialize``)."""
    dtype = xs[0].dtype
    int_type = {8: jnp.int64, 4: jnp.int32, 2: jnp.int16}[dtype.itemsize]
    bits = [lax.bitcast_convert_type(x, int_type) for x in xs]
    # one variadic reduction, an output per value: stacking the values into one array first makes
    # XLA compute them inside a concatenate loop, which does not vectorize
    zero = jnp.zeros((), int_type)
    out = lax.reduce([jnp.stack([b, jnp.zeros_like(b)]) for b in bits], [zero] * len(bits),
                     _bitwise_or(len(bits)), (0,))
    return tuple(lax.bitcast_convert_type(o, dtype) for o in out)


@functools.lru_cache(maxsize=None)
def _bitwise_or(count):
    """The reduction of ``materialize`` over ``count`` values. One function object per count:
    ``lax.reduce`` caches its compiled computation by this object, so outside ``jit`` (eager
    calls) a new function each time would compile the reduction again on every call."""
    return lambda a, b: tuple(x | y for x, y in zip(a, b))


# sin, cos and atan2 written as polynomials in elementwise operations (the module docstring says
# where and why).

def _pio2_parts(head_bits, dtype):
    """pi/2 = p1 + p2 + p3 in ``dtype``, p1 and p2 with ``head_bits`` significant bits (so that
    k * p1 and k * p2 are exact for integers |k| < 2^(mantissa - head_bits))."""
    rest = Fraction(_PI_DIGITS) / 2
    parts = []
    for last in (False, False, True):
        f = float(rest)
        if not last:
            m, e = math.frexp(f)
            f = math.ldexp(math.floor(m * 2**head_bits) / 2**head_bits, e)
        f = float(np.asarray(f, dtype))
        parts.append(f)
        rest -= Fraction(f)
    return tuple(parts)


_PI_DIGITS = "3.14159265358979323846264338327950288419716939937510582097494459230781640628620899863"
_PIO2 = {8: _pio2_parts(33, np.float64), 4: _pio2_parts(12, np.float32)}
_SIN = tuple((-1) ** k / math.factorial(2 * k + 1) for k in range(1, 8))  # Taylor, to r^15
_COS = tuple((-1) ** k / math.factorial(2 * k) for k in range(2, 9))  # to r^16
_ATAN = tuple((-1) ** k / (2 * k + 1) for k in range(1, 12))  # to h^23
_TAN_PI_8 = math.sqrt(2.0) - 1.0


def _horner(z, coefficients):
    acc = coefficients[-1]
    for c in coefficients[-2::-1]:
        acc = acc * z + c
    return acc


def _sincos_values(x):
    """(sin x, cos x). x = k pi/2 + r, |r| <= pi/4 (Cody-Waite, three parts of pi/2); Taylor
    polynomials in r (truncation below 5e-17 at pi/4). In float64 within 2 ulp of NumPy for
    |x| <= 2^20 pi/2 (1.6e6 rad), beyond that the error grows as |x| 2^-53; the values stay on the
    unit circle for every finite x (r is clipped). Float32: exact reduction to |x| < 6400 rad."""
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    p1, p2, p3 = _PIO2[8 if x.dtype.itemsize >= 8 else 4]
    k = jnp.round(x * (2.0 / math.pi))
    r = jnp.clip(((x - k * p1) - k * p2) - k * p3, -0.79, 0.79)
    z = r * r
    s = r + r * z * _horner(z, _SIN)
    half = 0.5 * z
    w = 1.0 - half
    c = w + (((1.0 - w) - half) + z * z * _horner(z, _COS))  # 1 - z/2 without losing its low bits
    q = (k - 4.0 * jnp.floor(0.25 * k)).astype(jnp.int32)  # k mod 4, exact for any integer k
    odd = (q & 1) == 1
    sin, cos = jnp.where(odd, c, s), jnp.where(odd, s, c)
    return jnp.where(q >= 2, -sin, sin), jnp.where((q == 1) | (q == 2), -cos, cos)


@jax.jit
def _sincos_stored(x):
    """``materialize(*_sincos_values(x))``, traced once per shape: within a traced program a call is one
    operation, which XLA inlines. The dozens of angles of a program with a motion to rest would otherwise trace
    the polynomials again each, a quarter of its operations."""
    return materialize(*_sincos_values(x))


@jax.custom_jvp
def sincos(x):
    """(sin x, cos x) as vectorizable polynomials (see ``_sincos_values``), stored once
    (``materialize``: else XLA copies the polynomial into every loop that reads the values, and
    compiles each copy); derivative exact in terms of the values."""
    return _sincos_stored(x)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    sin, cos = sincos(x)
    return (sin, cos), (cos * dx, -sin * dx)


def _atan2_values(y, x):
    """atan2(y, x) in (-pi, pi]: t = min/max of |x|, |y| in [0, 1], moved to |t| <= tan(pi/8) by
    atan t = pi/4 + atan((t - 1)/(t + 1)), halved by atan t = 2 atan(t / (1 + sqrt(1 + t^2))),
    then a Taylor polynomial (truncation below 1e-17). Within 4 ulp of NumPy in float64. The
    origin gives 0 (atan2(+-0, x < 0) = +-pi as in C)."""
    ax, ay = jnp.abs(x), jnp.abs(y)
    steep = ay > ax
    lo, hi = jnp.where(steep, ax, ay), jnp.where(steep, ay, ax)
    t = lo / jnp.where(hi > 0, hi, 1.0)
    wide = t > _TAN_PI_8
    t = jnp.where(wide, (t - 1.0) / (t + 1.0), t)
    h = t / (1.0 + jnp.sqrt(1.0 + t * t))
    z = h * h
    a = 2.0 * (h + h * z * _horner(z, _ATAN))
    a = jnp.where(wide, math.pi / 4 + a, a)
    a = jnp.where(steep, math.pi / 2 - a, a)
    a = jnp.where(x < 0, math.pi - a, a)
    return jnp.where(jnp.signbit(y), -a, a)


@jax.jit
def _atan2_stored(y, x):
    """``materialize(_atan2_values(y, x))[0]``, traced once per shape (as ``_sincos_stored``)."""
    return materialize(_atan2_values(y, x))[0]


@jax.custom_jvp
def _atan2(y, x):
    """atan2 as a vectorizable polynomial (``_atan2_values``); derivative
    (x dy - y dx) / (x^2 + y^2), 0 at the origin."""
    y, x = jnp.broadcast_arrays(y, x)
    return _atan2_stored(y, x)


@_atan2.defjvp
def _atan2_jvp(primals, tangents):
    (y, x), (dy, dx) = primals, tangents
    r2 = x * x + y * y
    return _atan2(y, x), safe_div(x * dy - y * dx, r2)


def trig(yaw, pitch, roll):
    """(cos yaw, sin yaw, cos pitch, sin pitch, cos roll, sin roll): the six values of
    ``rotation``, each evaluated and stored once per row by ``sincos``, whose derivative reuses
    them (d cos = -sin, d sin = cos)."""
    yaw, pitch, roll = jnp.broadcast_arrays(yaw, pitch, roll)
    (sz, cz), (sy, cy), (sx, cx) = sincos(yaw), sincos(pitch), sincos(roll)
    return cz, sz, cy, sy, cx, sx


def rotation_c(cz, sz, cy, sy, cx, sx):
    """R (components) from ``trig``'s six values."""
    return (
        (cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx),
        (sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx),
        (-sy, cy * sx, cy * cx),
    )


def rotation(yaw, pitch, roll):
    """R = Rz(yaw) Ry(pitch) Rx(roll): body (ISO 8855) -> global."""
    return from_rows(rotation_c(*trig(yaw, pitch, roll)))


def safe_norm(v):
    """|v|, with gradient 0 (not NaN) at v = 0 (``safe_sqrt`` of v.v)."""
    sq = dot(v, v) if isinstance(v, (tuple, list)) or v.shape[-1] == 3 else jnp.sum(v * v, -1)
    return safe_sqrt(sq)


def safe_sqrt(x):
    """sqrt(x) where x > 0, else 0, with gradient 0 (not NaN) where x <= 0.

    sqrt(max(x, tiny)) - sqrt(tiny), tiny the smallest normal number (the difference is sqrt(x) to the
    last bit for x above ~1e-276 in float64, ~3e-24 in float32): no test of x, so no stand-in. A
    double-where (sqrt(where(x > 0, x, 1)) where x > 0) went wrong where x is 0 up to rounding: XLA
    may compute one expression in two fused loops and round it differently in each (where the
    compiler contracts a*b + c into one rounding in one loop only). x was then 0 in the test and not in
    the sqrt, or the other way round, and the result sqrt(1) = 1: a single-case ``ks_jax.solve`` gave
    the manual's inline crash (ks_jax/cases/seed_001_lucid_kia.toml) 1.1 N s of tangential impulse instead of 0."""
    tiny = jnp.finfo(jnp.result_type(x, float)).tiny
    return jnp.sqrt(jnp.maximum(x, tiny)) - math.sqrt(float(tiny))


def safe_div(a, b, fallback=0.0):
    """a / b where b != 0, else ``fallback``, with finite gradients."""
    nz = b != 0
    return jnp.where(nz, a / jnp.where(nz, b, 1.0), fallback)


def safe_atan2(y, x):
    """atan2(y, x) in (-pi, pi] as a vectorizable polynomial (``_atan2_values``), with 0 (value and
    gradient) at the origin; derivative (x dy - y dx) / (x^2 + y^2) elsewhere."""
    zero = (x == 0) & (y == 0)
    return jnp.where(zero, 0.0, _atan2(y, jnp.where(zero, 1.0, x)))


def degrees_0_360(rad):
    """Radians in [-pi, pi] (a ``safe_atan2``) -> degrees in [0, 360). No jnp.mod: on a CPU it is a
    scalar libm call per value. Where a value is put to 0 (-0.0, as a frontal force gives, and a
    tiny negative angle that rounds to 360) its derivative is kept: the angle's rate of turning."""
    d = jnp.degrees(rad)
    d = jnp.where(d < 0.0, d + 360.0, d)
    return _value_with_gradient(jnp.where((d >= 360.0) | (d == 0.0), 0.0, d), d)


def plain_zero(x):
    """``x`` with -0.0 written 0.0 (a result that no impulse made is 0, not "-0" in a file); its
    derivative is that of ``x`` everywhere, 0 included."""
    return _value_with_gradient(jnp.where(x == 0.0, 0.0, x), x)


def _value_with_gradient(value, x):
    """``value`` (equal to ``x`` or a corrected form of it, such as -0.0 -> 0.0) with the derivative of
    ``x``: a ``jnp.where`` alone would make the derivative 0 where it corrects. x - stop_gradient(x) is
    +0.0 for every finite x, so the value is ``value`` exactly."""
    return lax.stop_gradient(value) + (x - lax.stop_gradient(x))
