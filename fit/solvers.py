"""Least-squares solvers over a batch of rows (one row = one start of one case).

``fun``: (z (n,), data) -> (r (m,), aux) for ONE row: the whitened residuals and anything to
carry (predictions, status); ``data`` is that row's slice of a pytree with a leading R (the
case inputs, evidence values, ...). Every solver takes a batch of starts z0 (R, n) and returns a
``SolveState`` whose leaves have a leading R: the final z, r, aux, the Jacobian dr/dz there,
the cost 0.5 |r|^2, whether a convergence test passed, and the iterations used.

``levenberg_marquardt`` (the default) is written batched: one ``lax.while_loop`` over all rows
whose body evaluates ``vmap(jacfwd(fun))`` once. (A vmapped per-row while_loop computes the
same, but JAX then re-traces the loop body to batch it, which doubled the compile time of this
engine-sized body.) Rows that have converged are frozen; the loop ends when all have, or at
``max_iter``.

``optax_lbfgs`` and ``optax_adam`` minimise the same cost 0.5 |r|^2 with optax (per-row
while_loop, vmapped: a line search cannot be shared between rows). They are here for the
measured comparison in ``benchmarks/bench_fit.py --compare`` (docs/fit.md).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax

HIGHEST = jax.lax.Precision.HIGHEST  # the products of J at their dtype's full precision (``model.linalg.mm``)


class SolveState(NamedTuple):
    z: jax.Array  # (R, n) final unconstrained parameters
    r: jax.Array  # (R, m) whitened residuals at z
    aux: Any  # pytree with leading R, from fun at z
    jacobian: jax.Array  # (R, m, n) dr/dz at z
    cost: jax.Array  # (R,) 0.5 |r|^2 (inf where not finite)
    converged: jax.Array  # (R,) bool
    iterations: jax.Array  # (R,) int32


LAM_MAX = 1e12  # the Levenberg-Marquardt damping's ceiling


def tolerances(dtype):
    """(gtol, ftol, ctol) for a dtype. gtol: the cosine between r and every Jacobian column
    (scale-free: the same for z and for the physical unknowns); ftol: the relative cost decrease
    of an accepted step below which the fit has stalled; ctol: a cost this small is an exact fit
    (every residual below ~1.4e-5 sigma in float64, ~1.4e-3 in float32: evidence copied from a solve
    to seven digits leaves ~1e-7 sigma, where rounding stops the cosine test short of gtol)."""
    if jnp.finfo(dtype).eps < 1e-10:
        return 1e-8, 1e-10, 1e-10
    return 1e-4, 1e-6, 1e-6


def _cost(r):
    c = 0.5 * jnp.sum(r * r, -1)
    return jnp.where(jnp.isfinite(c), c, jnp.inf)


def gradient_test(J, r, cost, gtol, ctol):
    """(R,) bool: max_i |J_i . r| <= gtol |J_i| |r| for every column i, or cost <= ctol."""
    g = jnp.einsum("...mn,...m->...n", J, r, precision=HIGHEST)
    col = jnp.sqrt(jnp.sum(J * J, -2))
    rn = jnp.sqrt(2.0 * jnp.where(jnp.isfinite(cost), cost, 0.0))[..., None]
    return (jnp.all(jnp.abs(g) <= gtol * col * rn + 1e-30, -1) | (cost <= ctol)) & jnp.isfinite(cost)


def _linearise(fun):
    def with_r(z, data):
        r, aux = fun(z, data)
        return r, (r, aux)

    return jax.vmap(jax.jacfwd(with_r, has_aux=True))


def levenberg_marquardt(fun, z0, data, max_iter: int = 100, z_min=None, z_max=None) -> SolveState:
    """Damped Gauss-Newton (Levenberg-Marquardt) from the starts z0 (R, n).

    Step per row: (J^T J + lam D) dz = -J^T r, D = diag(J^T J) floored at 1e-9 of its largest
    entry (an unknown the residuals do not see still gets a finite, damped step). Accept when the
    cost falls; lam *= max(1/3, 1 - (2 rho - 1)^3) on acceptance, lam *= nu, nu *= 2 on rejection
    (Nielsen 1999). Converged: the gradient test (``gradient_test``), an accepted step that
    lowers the cost by less than ftol of it, or a rejected step at the damping's ceiling
    ``LAM_MAX``. z is clipped to [z_min, z_max] (n,) (keeps the bound transforms out of underflow).
    One Jacobian per iteration: (J, r) are evaluated at the trial point only (the first trial is z0).
    """
    dtype = z0.dtype
    R, n = z0.shape
    gtol, ftol, ctol = tolerances(dtype)
    lin = _linearise(fun)
    z_min = jnp.full(n, -jnp.inf, dtype) if z_min is None else z_min
    z_max = jnp.full(n, jnp.inf, dtype) if z_max is None else z_max
    # the shapes of one row's residuals and aux, traced without the Jacobian and the batch (the loop
    # body traces ``lin`` itself): J is (R, m, n), every leaf has a leading R
    r1, aux1 = jax.eval_shape(fun, z0[0], jax.tree_util.tree_map(lambda x: x[0], data))
    J0 = jax.ShapeDtypeStruct((R,) + r1.shape + (n,), r1.dtype)
    r0, aux0 = jax.tree_util.tree_map(lambda s: jax.ShapeDtypeStruct((R,) + s.shape, s.dtype), (r1, aux1))
    zeros = lambda s: jnp.zeros(s.shape, s.dtype)  # noqa: E731

    def cond(s):
        return (s["it"] < max_iter) & ~jnp.all(s["done"])

    def body(s):
        J_t, (r_t, aux_t) = lin(s["trial"], data)
        ok = jnp.all(jnp.isfinite(J_t), (1, 2)) & jnp.all(jnp.isfinite(r_t), 1)
        c_t = jnp.where(ok, _cost(r_t), jnp.inf)
        live = ~s["done"]
        first = s["iterations"] == 0
        accept = live & (c_t < s["cost"])
        rho = (s["cost"] - c_t) / jnp.where(s["predicted"] > 0, s["predicted"], 1.0)
        lam_acc = jnp.where(first, s["lam"], s["lam"] * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3))
        lam = jnp.where(live, jnp.clip(jnp.where(accept, lam_acc, s["lam"] * s["nu"]), 1e-12, LAM_MAX), s["lam"])
        nu = jnp.where(accept, 2.0, jnp.where(live, s["nu"] * 2.0, s["nu"]))
        stalled = accept & ~first & (s["cost"] - c_t <= ftol * s["cost"])
        # no step lowers the cost even at the largest damping (a steepest-descent step of ~1e-12 of
        # the Gauss-Newton scale): a minimum to rounding
        stalled = stalled | (live & ~first & ~accept & (s["lam"] * s["nu"] >= LAM_MAX))
        pick = lambda new, old: jnp.where(accept.reshape((R,) + (1,) * (new.ndim - 1)), new, old)  # noqa: E731
        z = pick(s["trial"], s["z"])
        J = pick(J_t, s["J"])
        r = pick(r_t, s["r"])
        aux = jax.tree_util.tree_map(pick, aux_t, s["aux"])
        cost = jnp.where(accept, c_t, s["cost"])
        done = s["done"] | (live & (gradient_test(J, r, cost, gtol, ctol) | stalled | (first & ~ok)))
        g = jnp.einsum("rmn,rm->rn", J, r, precision=HIGHEST)
        H = jnp.einsum("rmi,rmj->rij", J, J, precision=HIGHEST)
        d = jnp.diagonal(H, axis1=1, axis2=2)
        d = jnp.maximum(d, 1e-9 * jnp.max(d, 1, keepdims=True) + jnp.finfo(dtype).tiny)
        A = H + lam[:, None, None] * (d[:, :, None] * jnp.eye(n, dtype=dtype))
        dz = -jnp.linalg.solve(A, g[..., None])[..., 0]
        dz = jnp.where(jnp.all(jnp.isfinite(dz), 1, keepdims=True), dz, 0.0)
        trial = jnp.clip(z + dz, z_min, z_max)
        dz = trial - z
        predicted = -(jnp.sum(g * dz, 1) + 0.5 * jnp.einsum("ri,rij,rj->r", dz, H, dz, precision=HIGHEST))
        return {"z": z, "J": J, "r": r, "aux": aux, "cost": cost, "trial": trial, "predicted": predicted,
                "lam": lam, "nu": nu, "done": done, "iterations": s["iterations"] + live.astype(jnp.int32),
                "it": s["it"] + 1}

    init = {"z": z0, "J": zeros(J0), "r": zeros(r0), "aux": jax.tree_util.tree_map(zeros, aux0),
            "cost": jnp.full(R, jnp.inf, dtype), "trial": jnp.clip(z0, z_min, z_max),
            "predicted": jnp.zeros(R, dtype), "lam": jnp.full(R, 1e-3, dtype), "nu": jnp.full(R, 2.0, dtype),
            "done": jnp.zeros(R, bool), "iterations": jnp.zeros(R, jnp.int32), "it": jnp.int32(0)}
    s = jax.lax.while_loop(cond, body, init)
    return SolveState(s["z"], s["r"], s["aux"], s["J"], s["cost"], s["done"] & jnp.isfinite(s["cost"]),
                      s["iterations"])


def _optax_rows(one_row, fun, z0, data, max_iter, z_min, z_max):
    """Run an unbatched optax loop per row (vmapped), then linearise once at the end."""
    gtol, _, ctol = tolerances(z0.dtype)
    z_min = jnp.full(z0.shape, -jnp.inf, z0.dtype) if z_min is None else jnp.broadcast_to(z_min, z0.shape)
    z_max = jnp.full(z0.shape, jnp.inf, z0.dtype) if z_max is None else jnp.broadcast_to(z_max, z0.shape)

    def row(z, d, lo, hi):
        return one_row(lambda z: _cost(fun(jnp.clip(z, lo, hi), d)[0]), z, max_iter)

    z, it = jax.vmap(row)(z0, data, z_min, z_max)
    z = jnp.clip(z, z_min, z_max)
    J, (r, aux) = _linearise(fun)(z, data)
    cost = _cost(r)
    # optax never reaches the LM's tight cosine test; judge it 1000 times looser
    return SolveState(z, r, aux, J, cost, gradient_test(J, r, cost, 1e3 * gtol, ctol), it)


def _lbfgs_row(cost_fn, z0, max_iter):
    ctol = tolerances(z0.dtype)[2]
    opt = optax.lbfgs()
    vg = optax.value_and_grad_from_state(cost_fn)

    def cond(s):
        return (s[2] < max_iter) & ~s[3]

    def body(s):
        z, st, it, _ = s
        value, grad = vg(z, state=st)
        updates, st = opt.update(grad, st, z, value=value, grad=grad, value_fn=cost_fn)
        done = (jnp.max(jnp.abs(grad)) <= 1e-12) | (value <= ctol) | ~jnp.isfinite(value)
        return optax.apply_updates(z, updates), st, it + 1, done

    z, _, it, _ = jax.lax.while_loop(cond, body, (z0, opt.init(z0), jnp.int32(0), jnp.bool_(False)))
    return z, it


def _adam_row(cost_fn, z0, max_iter, learning_rate=0.05):
    ctol = tolerances(z0.dtype)[2]
    opt = optax.adam(learning_rate)
    grad_fn = jax.value_and_grad(cost_fn)

    def cond(s):
        return (s[2] < max_iter) & ~s[3]

    def body(s):
        z, st, it, _ = s
        value, grad = grad_fn(z)
        grad = jnp.where(jnp.isfinite(grad), grad, 0.0)
        updates, st = opt.update(grad, st, z)
        done = (jnp.max(jnp.abs(grad)) <= 1e-12) | (value <= ctol)
        return optax.apply_updates(z, updates), st, it + 1, done

    z, _, it, _ = jax.lax.while_loop(cond, body, (z0, opt.init(z0), jnp.int32(0), jnp.bool_(False)))
    return z, it


def optax_lbfgs(fun, z0, data, max_iter: int = 200, z_min=None, z_max=None) -> SolveState:
    """L-BFGS (optax, zoom line search) on 0.5 |r|^2 per row, until the gradient vanishes or
    ``max_iter``; converged by the gradient test with gtol x 1000."""
    return _optax_rows(_lbfgs_row, fun, z0, data, max_iter, z_min, z_max)


def optax_adam(fun, z0, data, max_iter: int = 2000, z_min=None, z_max=None) -> SolveState:
    """Adam (optax, learning rate 0.05 in z) on 0.5 |r|^2 per row for ``max_iter`` steps."""
    return _optax_rows(_adam_row, fun, z0, data, max_iter, z_min, z_max)


SOLVERS = {"lm": levenberg_marquardt, "lbfgs": optax_lbfgs, "adam": optax_adam}
