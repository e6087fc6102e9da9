"""``ks_jax.sum_over_rows``: a batched loss that sums rows, whose gradient is computed chunk by chunk: its
value, gradient, forward mode and second derivatives are those of the plain sum, and per-row gradients."""

from __future__ import annotations


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax import backend
from samples import reference_jit, with_bad_rows
import kit


def _evidence_row_loss(v1, s1, v2, s2, c, target):
    r = ks_jax.exchange(v1, s1, v2, s2, c)
    ok = r.contact.status == 0
    delta_v = jnp.where(ok, r.vehicles[0].delta_v_magnitude, target)  # NaN in a bad row: no NaN times the target
    return jnp.where(ok, (delta_v - target) ** 2 + r.vehicles[1].speed_after ** 2 + 1e-4 * r.contact.energy_loss, 0.0)


@pytest.mark.slow
def test_sum_over_rows_equals_the_sum_and_per_row_gradients(random_cases):
    """Chunks of 64 rows over 150 (the last chunk padded), a vehicle and an evidence target shared by
    every row, rows with invalid inputs: the value is the plain sum, the gradients are the per-row
    gradients (summed over the rows for the shared inputs), zero and finite in the bad rows, and a
    central difference agrees."""
    cases = with_bad_rows(random_cases["full"][:150])
    v1, s1, v2, s2, c = kit.inputs(cases)
    shared = jax.tree_util.tree_map(lambda x: x[0], v2)
    axes = (0, 0, None, 0, 0, None)
    loss = ks_jax.sum_over_rows(_evidence_row_loss, in_axes=axes, chunk=64, plan=backend.Plan("cpu"))  # fenced chunks
    target = jnp.asarray(4.0)

    def plain(*a):
        return jnp.sum(jax.vmap(_evidence_row_loss, in_axes=axes)(*a))

    def checks(*a):
        """In one program (one compile): the chunked value and gradients, and their references: the jitted
        ``loss`` (the custom JVP's forward), the plain sum and the per-row gradients, each its own computation."""
        return (jax.value_and_grad(loss, argnums=(1, 2, 4, 5))(*a), loss(*a), plain(*a),
                jax.vmap(jax.grad(_evidence_row_loss, argnums=(1, 2, 4, 5)), in_axes=axes)(*a))

    traced = reference_jit(checks).trace(v1, s1, shared, s2, c, target)
    assert "cond[" in str(traced.jaxpr)
    program = traced.lower().compile()
    (value, grads), jitted, plain_value, per_row = program(v1, s1, shared, s2, c, target)
    np.testing.assert_allclose(float(value), float(plain_value), rtol=1e-13)
    np.testing.assert_allclose(float(jitted), float(plain_value), rtol=1e-13)
    reference = (per_row[0], jax.tree_util.tree_map(lambda x: np.sum(np.asarray(x), 0), per_row[1]), per_row[2],
                 np.sum(np.asarray(per_row[3])))
    for a, b in zip(jax.tree_util.tree_leaves(grads), jax.tree_util.tree_leaves(reference)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-10)
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(grads))
    for bad in (63, 100):
        assert all(np.all(np.asarray(x)[bad] == 0) for x in jax.tree_util.tree_leaves((grads[0], grads[2])))
    h = 1e-6
    fd = (program(v1, s1, shared, s2, c, target + h)[2] - program(v1, s1, shared, s2, c, target - h)[2]) / (2 * h)
    np.testing.assert_allclose(float(grads[3]), float(fd), rtol=1e-6)


@pytest.mark.slow
def test_sum_over_rows_forward_mode_and_second_derivatives(random_cases):
    """Forward mode against central differences of the plain sum, and the Hessian of the chunked sum
    (forward over reverse) against central differences of its forward mode."""
    v1, s1, v2, s2, c = kit.inputs(random_cases["principal"][:100])
    loss = ks_jax.sum_over_rows(_evidence_row_loss, in_axes=(0, 0, 0, 0, 0, None), chunk=32)

    def scaled(p, fn):
        return fn(v1, s1._replace(velocity=s1.velocity * p[0]), v2, s2, c._replace(friction=c.friction * p[1]), 3.0)

    def plain(*args):
        return jnp.sum(jax.vmap(_evidence_row_loss, in_axes=(0, 0, 0, 0, 0, None))(*args))

    p, e, h = jnp.array([1.0, 0.9]), np.eye(2), 1e-6

    def checks(p, t):
        """One program (one compile) for the plain sum and the chunked sum's derivative along t (the Hessian, whose
        run costs more, is a program of its own)."""
        return scaled(p, plain), jax.jvp(lambda q: scaled(q, loss), (p,), (t,))[1]

    program = reference_jit(checks)
    plain_value, jvp = (lambda p, t: program(p, t)[0]), (lambda p, t: program(p, t)[1])
    fd = (plain_value(p + h * e[0], e[0]) - plain_value(p - h * e[0], e[0])) / (2 * h)
    np.testing.assert_allclose(float(jvp(p, e[0])), float(fd), rtol=1e-6)
    hessian = np.asarray(reference_jit(jax.hessian(lambda q: scaled(q, loss)))(p))
    for j in range(2):
        for k in range(2):  # d/dp_k of the derivative along p_j
            fd = (float(jvp(p + h * e[k], e[j])) - float(jvp(p - h * e[k], e[j]))) / (2 * h)
            np.testing.assert_allclose(hessian[j, k], fd, rtol=1e-5, atol=1e-6 * np.abs(hessian).max())
    assert abs(float(hessian[0, 1])) > 1.0  # the two parameters interact


@pytest.mark.slow
def test_sum_over_rows_rejects_bad_arguments(random_cases):
    args = kit.inputs(random_cases["principal"][:10])
    with pytest.raises(ValueError, match=r"chunk = 0: chunk must be a positive number of rows"):
        ks_jax.sum_over_rows(_evidence_row_loss, chunk=0)
    with pytest.raises(ValueError, match=r"in_axes\[5\] = 1: each entry must be 0 \(batched\) or None"):
        ks_jax.sum_over_rows(_evidence_row_loss, in_axes=(0, 0, 0, 0, 0, 1))(*args, 3.0)
    with pytest.raises(ValueError, match=r"in_axes = \(0, None\) has 2 entries for 6 arguments"):
        ks_jax.sum_over_rows(_evidence_row_loss, in_axes=(0, None))(*args, 3.0)
    with pytest.raises(TypeError, match=r"fn returns shape \(3,\) per row; it must return a scalar"):
        # traced, not run: the shape check is made while tracing (eagerly, each operation would compile)
        jax.eval_shape(ks_jax.sum_over_rows(lambda *a: ks_jax.exchange(*a).vehicles[0].delta_v), *args)


def test_sum_over_rows_forward_mode_with_a_python_number():
    """jvp and jacfwd with a Python float as the shared argument (as docs/sweeps.md passes a measured value):
    d/dt sum_k (x_k - t)^2 = -2 sum_k (x_k - t), by hand."""
    loss = ks_jax.sum_over_rows(lambda x, t: (x - t) ** 2, in_axes=(0, None))
    x = jnp.arange(5.0)
    value, slope = jax.jvp(lambda t: loss(x, t), (3.0,), (1.0,))
    assert float(value) == 15.0 and float(slope) == 10.0
    assert float(jax.jacfwd(lambda t: loss(x, t))(3.0)) == 10.0 == float(jax.grad(lambda t: loss(x, t))(3.0))
