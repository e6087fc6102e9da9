"""The kernel's own sin/cos and atan2 (``linalg.sincos``, ``linalg.safe_atan2``) against NumPy's libm,
in units in the last place, and their derivatives against the exact ones. ``safe_atan2`` is the polynomial
atan2 everywhere but at the origin, so its tests away from the origin are those of the polynomial."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ks_jax.model import results as derived
from ks_jax.model import linalg as la
from ks_jax.model.matrix import inverse_inertia_world


def ulps(got, want):
    got, want = np.asarray(got, np.float64), np.asarray(want)
    return np.abs(got - want) / np.spacing(np.abs(want).astype(want.dtype)).astype(np.float64)


@pytest.mark.parametrize("scale", [1.0, 10.0, 1e3, 1e6])
def test_sincos_within_2_ulp_of_numpy(scale):
    x = np.random.default_rng(1).uniform(-scale, scale, 200_000)
    # quadrant boundaries, where the reduction changes k, and the zeros of sin and cos
    x = np.concatenate([x, np.arange(-64, 65) * (np.pi / 4), np.nextafter(np.arange(-8, 9) * (np.pi / 2), 10)])
    sin, cos = jax.jit(la.sincos)(jnp.asarray(x))
    # near a zero of sin/cos the absolute error is what the reduction allows: 2 ulp of pi/2 * k
    floor = 2 * np.spacing(np.maximum(np.abs(x), 1.0))
    for got, want in ((sin, np.sin(x)), (cos, np.cos(x))):
        err = np.abs(np.asarray(got) - want)
        assert np.all((err <= 2 * np.spacing(np.abs(want))) | (err <= floor)), ulps(got, want).max()


@pytest.mark.slow
def test_sincos_exact_points_and_huge_arguments():
    sin, cos = la.sincos(jnp.array([0.0, -0.0, 1e-300, 0.5]))
    np.testing.assert_array_equal(np.asarray(sin)[:3], [0.0, 0.0, 1e-300])
    np.testing.assert_array_equal(np.asarray(cos)[:3], [1.0, 1.0, 1.0])
    # past 2^20 pi/2 the reduction is no longer exact; the values stay finite and on the circle
    big = jnp.array([1e7, -3e12, 1e300, -1.7e308])
    sin, cos = la.sincos(big)
    assert np.all(np.isfinite(sin)) and np.all(np.isfinite(cos))
    np.testing.assert_allclose(np.asarray(sin) ** 2 + np.asarray(cos) ** 2, 1.0, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(la.sincos(jnp.array(1e7))), [np.sin(1e7), np.cos(1e7)], atol=1e-8)
    sin, cos = la.sincos(jnp.array([np.inf, np.nan]))
    assert np.all(np.isnan(sin)) and np.all(np.isnan(cos))


def test_sincos_float32():
    x = np.random.default_rng(2).uniform(-100, 100, 100_000).astype(np.float32)
    sin, cos = jax.jit(la.sincos)(jnp.asarray(x))
    assert sin.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(sin), np.sin(x.astype(np.float64)), atol=3e-7)
    np.testing.assert_allclose(np.asarray(cos), np.cos(x.astype(np.float64)), atol=3e-7)


def test_sincos_derivative_and_trig():
    x = jnp.linspace(-7.0, 7.0, 57)
    ds = jax.vmap(jax.grad(lambda t: la.sincos(t)[0]))(x)
    dc = jax.vmap(jax.grad(lambda t: la.sincos(t)[1]))(x)
    np.testing.assert_allclose(ds, np.cos(x), rtol=0, atol=2e-16)
    np.testing.assert_allclose(dc, -np.sin(x), rtol=0, atol=2e-16)
    # trig: the six values of the rotation, and its second derivative through sincos
    y, p, r = 0.3, -1.2, 2.9
    np.testing.assert_allclose(la.trig(y, p, r), [np.cos(y), np.sin(y), np.cos(p), np.sin(p), np.cos(r), np.sin(r)],
                               rtol=0, atol=2e-16)
    d2 = jax.grad(jax.grad(lambda t: la.sincos(t)[0]))(1.1)
    np.testing.assert_allclose(d2, -np.sin(1.1), rtol=1e-15)


@pytest.mark.parametrize("scale", [1.0, 1e-6, 1e6])
def test_atan2_within_4_ulp_of_numpy(scale):
    rng = np.random.default_rng(3)
    y, x = rng.standard_normal(200_000) * scale, rng.standard_normal(200_000)
    # the octant boundaries |y| = |x| tan(pi/8), |y| = |x|, and the axes
    t = np.tan(np.pi / 8)
    y = np.concatenate([y, [1.0, -1.0, t, -t, 1.0, 1.0, 0.0, -0.0, 0.0, -0.0, 1e-300, 5.0, -5.0]])
    x = np.concatenate([x, [1.0, -1.0, 1.0, -1.0, t, -t, 2.0, 2.0, -2.0, -2.0, -1.0, 0.0, 0.0]])
    got = np.asarray(jax.jit(la.safe_atan2)(jnp.asarray(y), jnp.asarray(x)))
    want = np.arctan2(y, x)
    assert np.all(np.abs(got - want) <= 4 * np.spacing(np.abs(want))), ulps(got, want).max()
    np.testing.assert_array_equal(np.signbit(got[-8:]), np.signbit(want[-8:]))


def test_atan2_derivative_and_safe_origin():
    y, x = 0.7, -1.9
    gy, gx = jax.grad(la.safe_atan2, argnums=(0, 1))(y, x)
    np.testing.assert_allclose([gy, gx], [x / (x * x + y * y), -y / (x * x + y * y)], rtol=1e-15)
    value, grads = jax.value_and_grad(la.safe_atan2, argnums=(0, 1))(0.0, 0.0)
    assert value == 0.0 and grads == (0.0, 0.0)


def test_degrees_and_clock():
    rad = jnp.array([0.0, -0.0, np.pi, -np.pi, -1e-17, np.pi / 2, -np.pi / 2])
    np.testing.assert_allclose(la.degrees_0_360(rad), [0.0, 0.0, 180.0, 180.0, 0.0, 90.0, 270.0], atol=1e-12)
    assert np.all(np.asarray(la.degrees_0_360(rad)) < 360.0)
    pdof = jnp.array([0.0, 14.9, 15.1, 90.0, 344.0, 346.0, 359.99])
    want = [12 if round(p / 30) % 12 == 0 else round(p / 30) % 12 for p in np.asarray(pdof)]
    np.testing.assert_array_equal(derived.clock(pdof), want)
    assert math.isclose(float(la.degrees_0_360(la.safe_atan2(-1.0, 0.0))), 270.0)


@pytest.mark.slow
def test_corrected_zeros_keep_their_derivative():
    """-0.0 is written 0.0 (and an angle that rounds to 360 deg is 0), but the derivative stays that of
    the uncorrected value (d/dx of degrees(x) is 180/pi, d/dx of -x*x/2 + 3x is 3 at 0): a plain
    ``jnp.where`` would make it 0 exactly there."""
    values, grads = jax.vmap(jax.value_and_grad(lambda r: la.degrees_0_360(r)))(jnp.array([-0.0, 0.0, -1e-17, 0.3]))
    np.testing.assert_array_equal(np.signbit(values), False)
    np.testing.assert_array_equal(values[:3], 0.0)
    np.testing.assert_allclose(grads, 180.0 / np.pi, rtol=1e-15)
    value, grad = jax.value_and_grad(lambda x: la.plain_zero(-0.5 * x * x * 0.0 - 0.0 * x))(2.0)
    assert value == 0.0 and not np.signbit(value) and grad == 0.0
    f = lambda x: la.plain_zero(-(x * x) / 2 + 3 * x)  # noqa: E731
    assert np.signbit(float(-(0.0 * 0.0) / 2 + 3 * -0.0)) and not np.signbit(float(f(-0.0)))
    assert float(jax.grad(f)(-0.0)) == 3.0 and float(jax.grad(f)(1.0)) == 2.0 and float(f(1.0)) == 2.5


@pytest.mark.slow
@pytest.mark.parametrize("diagonal", [False, True])
def test_world_inverse_inertia_derivative_matches_plain_autodiff(diagonal):
    """The hand-written tangent of R I^-1 R^T against autodiff of jnp.linalg.inv and the rotation."""
    rng = np.random.default_rng(5)
    a = rng.standard_normal((3, 3))
    inertia = np.array([500.0, 2500.0, 2700.0]) if diagonal else a @ a.T + np.diag([500.0, 2500.0, 2700.0])
    angles = (0.7, -0.2, 0.1)

    def ours(i, y, p, r):
        return inverse_inertia_world(i, la.trig(y, p, r))

    def plain(i, y, p, r):
        rot = jnp.array(la.rotation_c(jnp.cos(y), jnp.sin(y), jnp.cos(p), jnp.sin(p), jnp.cos(r), jnp.sin(r)))
        inv = jnp.diag(1.0 / i) if i.ndim == 1 else jnp.linalg.inv(i)
        return rot @ inv @ rot.T, rot

    primals = (jnp.asarray(inertia), *map(jnp.asarray, angles))
    tangent_i = rng.standard_normal(inertia.shape)
    tangent_i = tangent_i if diagonal else tangent_i + tangent_i.T
    tangents = (jnp.asarray(tangent_i), *map(jnp.asarray, rng.standard_normal(3)))
    (a1, r1), (da1, dr1) = jax.jvp(ours, primals, tangents)
    (a2, r2), (da2, dr2) = jax.jvp(plain, primals, tangents)
    np.testing.assert_allclose(a1, a2, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(r1, r2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(da1, da2, rtol=1e-10, atol=1e-20)
    np.testing.assert_allclose(dr1, dr2, rtol=0, atol=1e-15)
    # and reverse mode: the vector-Jacobian products agree
    ct = (jnp.asarray(rng.standard_normal((3, 3))), jnp.asarray(rng.standard_normal((3, 3))))
    g1 = jax.vjp(ours, *primals)[1](ct)
    g2 = jax.vjp(plain, *primals)[1](ct)
    for x, y in zip(g1, g2):
        np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-14)


@pytest.mark.slow
def test_eager_calls_do_not_compile_again(caplog):
    """Outside jit, sin/cos/atan2 run op by op; ``materialize``'s reduction must hit JAX's
    compilation cache on the second call (a fresh reduction function each call recompiled it,
    which made every eager exchange ~8x slower)."""
    x = jnp.linspace(-3.0, 3.0, 5)
    la.sincos(x), la.safe_atan2(x, x + 0.5), la.materialize(x, 2 * x)  # first calls may compile
    with caplog.at_level("WARNING"), jax.log_compiles():
        la.sincos(x), la.safe_atan2(x, x + 0.5), la.materialize(x, 2 * x)
    compiled = [r.getMessage() for r in caplog.records if "Compiling" in r.getMessage()]
    assert not compiled, compiled
