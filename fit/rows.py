"""The compiled solver over rows (a row: one start of one case): every start of every case in one jitted,
vmapped call, or in calls of one row count where a fit and its Monte Carlo refits share the program."""

from __future__ import annotations

import collections
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ks_jax.backend import Plan, row_placement
from ks_jax.compilation import quick_jit
from ks_jax.model.types import OK

from .problem import Problem, predict, to_x, wrap
from .solvers import SOLVERS

Z_LIMIT = 40.0  # |z| bound of a transform's saturating side: x within ~4e-18 of the bound (no underflow)


class Row(NamedTuple):
    """What the residuals of one row (one start of one case, or one case) are computed from: the case's
    ``inputs``, its evidence's ``values`` and ``sigmas`` (m,), its unknowns' bounds ``lo``, ``hi``, priors' means
    ``pm`` and 1 / sigmas ``pw`` (n,; 0 where none). Stacked along a leading axis: many rows."""

    inputs: object
    values: object
    sigmas: object
    lo: object
    hi: object
    pm: object
    pw: object


def whitened(problem: Problem, z, d: Row, smoothing):
    """The whitened residuals (m + n,) at the unconstrained unknowns z (n,) of row ``d``: the evidence's deviations
    in sigmas (angles wrapped), then the priors' (0 where none); and (predicted evidence (m,), the exchange's
    flags)."""
    return whitened_at(problem, to_x(z, d.lo, d.hi), d, smoothing)


def whitened_at(problem: Problem, x, d: Row, smoothing):
    """``whitened`` at the physical unknowns x (n,)."""
    pred, flags = predict(problem, d.inputs, x, smoothing)
    dev = jnp.stack([wrap(pred[k] - d.values[k], period) for k, (_, _, period) in enumerate(problem.evidence)])
    return jnp.concatenate([dev / d.sigmas, (x - d.pm) * d.pw]), (pred, flags)


class RowFits(NamedTuple):
    """The solver's outputs per row (one start of one case), each with a leading row axis (``fit_rows``), or
    shaped (cases, starts, ...) (``run_rows``); a selection of them, the others None (``rounds.Starts.best``).

    x, z: the unknowns at the end (n,), physical and unconstrained; cost: half the chi^2 there; converged: the
    solver's test passed (and the start did not stall); iterations; jacobian (m + n, n): of the whitened
    residuals with respect to x; residuals (m + n,); predicted (m,): the evidence's values; status, sliding,
    stick_ratio (|J_t| / J_n: the least friction that keeps a sticking contact sticking): the exchange's; stalled:
    the start ended where nothing collides and no unknown moves any evidence."""

    x: object = None
    z: object = None
    cost: object = None
    converged: object = None
    iterations: object = None
    jacobian: object = None
    residuals: object = None
    predicted: object = None
    status: object = None
    sliding: object = None
    stick_ratio: object = None
    stalled: object = None


@partial(quick_jit, static_argnames=("problem", "solver", "max_iter"))
def fit_rows(problem: Problem, solver: str, max_iter: int, inputs, values, sigmas, lo, hi, prior_mean, prior_weight,
              z0, smoothing):
    """One fit per row (rows = cases x starts, flattened): inputs [R], values/sigmas (R, m),
    lo/hi/prior_mean/prior_weight (R, n), z0 (R, n). Returns their ``RowFits``, each with a leading R.
    A start is "stalled", and not converged, where it ends without an exchange (status not "ok":
    separating, no contact) and no unknown moves any evidence there: its gradient is zero because
    nothing collides, not because it reached a fit."""

    def fun(z, d):
        return whitened(problem, z, d, smoothing)

    data = Row(inputs, values, sigmas, lo, hi, prior_mean, prior_weight)
    z_min = jnp.where(jnp.isfinite(lo), -Z_LIMIT, -jnp.inf)
    z_max = jnp.where(jnp.isfinite(hi), Z_LIMIT, jnp.inf)
    sol = SOLVERS[solver](fun, z0, data, max_iter, z_min, z_max)
    x = to_x(sol.z, lo, hi)
    # dr/dx = dr/dz / (dx/dz): the transforms are elementwise; dx/dz >= ~4e-18 thanks to Z_LIMIT
    dxdz = jax.jvp(lambda z: to_x(z, lo, hi), (sol.z,), (jnp.ones_like(sol.z),))[1]
    jac = jnp.where(dxdz[:, None, :] > 0, sol.jacobian / jnp.where(dxdz > 0, dxdz, 1.0)[:, None, :], 0.0)
    pred, (status, sliding, stick_ratio) = sol.aux
    m = len(problem.evidence)
    stalled = (status != OK) & jnp.all(jac[:, :m] == 0, axis=(1, 2))
    return RowFits(x=x, z=sol.z, cost=sol.cost, converged=sol.converged & ~stalled, iterations=sol.iterations,
                   jacobian=jac, residuals=sol.r, predicted=pred, status=status, sliding=sliding,
                   stick_ratio=stick_ratio, stalled=stalled)


STICKING_FRICTION = 1e3  # a friction no exchange of cars reaches: the stick impulse


@partial(quick_jit, static_argnames=("problem",))
def _stick_thresholds(problem: Problem, inputs, x, smoothing):
    """(R,): the least friction at which each row's exchange at ``x`` would stick: |J_t| / J_n of the stick
    impulse, from the exchange with friction raised to ``STICKING_FRICTION`` (NaN where it pulls)."""
    stick = x.at[:, problem.unknowns.index("contact.friction")].set(STICKING_FRICTION)
    _, (status, sliding, ratio) = jax.vmap(lambda xi, d: predict(problem, d, xi, smoothing))(stick, inputs)
    return jnp.where((status == OK) & ~sliding, ratio, jnp.nan)


def _padded(trees, dtype):
    """Every leaf of ``trees`` (each with a leading axis of B rows) as a ``dtype`` array whose rows are padded, by
    repeating the last, to a power of two (at least 8): so that batches of other sizes run the program already
    compiled."""
    B = len(jax.tree_util.tree_leaves(trees)[0])
    size = max(8, 1 << (B - 1).bit_length())

    def pad(a):
        a = np.asarray(a, np.float64)
        return jnp.asarray(np.concatenate([a, np.repeat(a[-1:], size - B, axis=0)]), dtype)

    return jax.tree_util.tree_map(pad, trees)


def stick_thresholds(problem: Problem, inputs, x, smoothing, dtype):
    """``_stick_thresholds`` of the rows of ``inputs`` (stacked CaseInputs [B]) at ``x`` (B, n), in one call
    (a call per case would wait on the device once per case), padded (``_padded``). NumPy (B,)."""
    rows, x_rows = _padded((inputs, x), dtype)
    return np.asarray(_stick_thresholds(problem, rows, x_rows, jnp.asarray(smoothing, dtype)))[:len(x)]


EDGE = 0.01  # the slide side of a contact that sticks: friction this fraction below the friction it needs


@partial(quick_jit, static_argnames=("problem",))
def _edge_jacobians(problem: Problem, data: Row, x, needed, smoothing):
    """(2, R, m + n, n): d(whitened residuals)/dx of each row at ``x`` with the friction raised to
    ``STICKING_FRICTION`` (the stick side, where friction moves nothing), then with it ``EDGE`` below ``needed``
    (R,), the friction the row's contact needs to stick (the slide side, where the contact just slides). One
    vmapped Jacobian over both sides' rows."""
    j = problem.unknowns.index("contact.friction")
    both = jnp.concatenate([x.at[:, j].set(STICKING_FRICTION), x.at[:, j].set(needed * (1.0 - EDGE))])
    twice = jax.tree_util.tree_map(lambda a: jnp.concatenate([a, a]), data)
    jac = jax.vmap(jax.jacfwd(lambda xi, d: whitened_at(problem, xi, d, smoothing)[0]))(both, twice)
    return jac.reshape((2, len(x)) + jac.shape[1:])


def edge_jacobians(problem: Problem, data: Row, x, needed, smoothing, dtype):
    """``_edge_jacobians`` of the rows of ``data`` (a ``Row`` of B stacked cases) at ``x`` (B, n) and ``needed``
    (B,), in one call, padded (``_padded``). NumPy (stick side, slide side), each (B, m + n, n)."""
    out = _edge_jacobians(problem, *_padded((data, x, needed), dtype), jnp.asarray(smoothing, dtype))
    out = np.asarray(out, np.float64)[:, :len(x)]
    return out[0], out[1]


def best_start(cost, converged):
    """Index of the best start along the last axis of ``cost`` and ``converged`` ((..., S)): the lowest cost,
    preferring a converged start whose cost ties it (the first such of the lowest cost). An int for one fit's
    (S,), else an array of the leading shape."""
    cost = np.asarray(cost, np.float64)
    cost = np.where(np.isfinite(cost), cost, np.inf)
    lowest = cost.min(axis=-1, keepdims=True)
    tie = cost <= lowest + 1e-9 * np.maximum(np.abs(lowest), 1.0) + 1e-12
    pick = tie & np.asarray(converged, bool)
    key = np.where(pick, cost, np.inf)
    first_pick = np.argmax(pick & (key == key.min(axis=-1, keepdims=True)), axis=-1)
    b = np.where(pick.any(axis=-1), first_pick, np.argmin(cost, axis=-1))
    return int(b) if b.ndim == 0 else b


AGREE_COST = 1e-6  # starts whose cost is within this fraction of the best (or 1e-9 absolute) reached the best fit


def _at_best(cost):
    """Which starts (costs (..., S), along the last axis) reached the best cost, to ``AGREE_COST``."""
    cost = np.asarray(cost, np.float64)
    finite = np.isfinite(cost)
    best = np.where(finite, cost, np.inf).min(axis=-1, keepdims=True)
    return finite & (cost <= best + AGREE_COST * np.maximum(best, 1.0) + 1e-9)


def count_at_best(cost):
    """How many starts (costs (..., S), along the last axis) reached the best cost, to ``AGREE_COST``: an int for
    one fit's (S,), else an array of the leading shape."""
    n = np.sum(_at_best(cost), axis=-1)
    return int(n) if n.ndim == 0 else n


FLIP_Z = 5.0  # a minimum this many standard deviations of a refit's perturbation above the best is never preferred


def several_minima(cost, converged):
    """Whether a fit's starts (costs (S,), inf where absent; ``converged`` (S,)) ended in more than one minimum
    that refits of perturbed evidence could prefer to the best (``monte_carlo.refit_perturbed``), or in none
    converged (nothing then says there is one). Perturbing the whitened residuals by e ~ N(0, 1) moves the
    difference of two minima's chi^2 by 2 (r_b - r_a) . e, of standard deviation 2 |r_b - r_a| <= 2 (sqrt(chi2_a)
    + sqrt(chi2_b)): a converged minimum whose chi^2 exceeds the best's by more than ``FLIP_Z`` times that is one
    no refit prefers, and one within ``AGREE_COST`` of the best is the best."""
    cost = np.asarray(cost, np.float64)
    ok = np.asarray(converged, bool) & np.isfinite(cost)
    if not ok.any():
        return True
    chi2 = 2.0 * cost[ok]
    best = chi2.min()
    near = chi2 - best < FLIP_Z * 2.0 * (np.sqrt(best) + np.sqrt(chi2))
    return bool(np.any(near & ~_at_best(cost[ok])))


def stack(trees):
    """Trees of the same structure (a batch's CaseInputs) as one tree of float64 NumPy arrays, the trees along a
    new leading axis."""
    return jax.tree_util.tree_map(lambda *xs: np.array(xs, np.float64), *trees)


# Rows (cases x starts) per call of the compiled solver in a fit with Monte Carlo refits, and on an accelerator's
# path in any fit, at most (there, for each device of the call). The fit and its refits then run in calls of one
# row count (the last call of each padded with copies of its last row), so that they share one compiled program
# instead of compiling one for each row count: compiling takes much longer than the calls themselves
# (``fit_block``). On the CPU's path a fit without refits is one call of exactly its rows. On a CPU a call's rows
# run one after another and calls of a few hundred rows lose little to one call of them all (docs/performance.md);
# on other devices a call's rows run side by side and its latency counts more, hence a larger block.
ROWS_PER_CALL = 500
ROWS_PER_CALL_ELSEWHERE = 8000  # on an accelerator's path


# Calls of a round dispatched ahead of the one whose results are read (``run_rows``)
IN_FLIGHT = 2


# Calls of at most this many rows compile with XLA's quicker settings (``compilation.quick_jit``): their compile is
# most of their time. Larger calls keep XLA's defaults, which run faster once compiled.
QUICK_ROWS = 500


def solver_for(block: int, devices):
    """The compiled solver for calls of ``block`` rows on ``devices``: up to ``QUICK_ROWS`` rows, quick to compile
    with the options of the devices' platform (the platform the program is compiled for; the plan's path is an
    argument of the program); more, with XLA's defaults."""
    return fit_rows.on(devices[0].platform) if block <= QUICK_ROWS else fit_rows.plain


def fit_block(fit_rows: int, refits: int, plan: Plan, devices: int = 1) -> int | None:
    """Rows per call of the solver for a fit of ``fit_rows`` rows (cases x starts), its further rounds of starts
    and its ``refits`` Monte Carlo refits, over ``devices`` devices.

    - The CPU's path without refits: None, each round in one call of its own rows, a further round in
      ``rounds.more_block``'s calls.
    - The CPU's path with refits: the fit's own row count, at most ``ROWS_PER_CALL``. A CPU runs a call's rows one
      after another, so refits in calls of a few rows cost what one call of them all does; the fit, the same fit
      with refits and its further rounds of starts then share the program that a fit without refits compiles.
    - An accelerator's path: the larger of the fit's rows and the refits, at most ``ROWS_PER_CALL_ELSEWHERE`` for
      each device (each then holds the rows one alone would), a call's rows running side by side there. Every call
      of the fit, its rounds and its refits holds that many rows, a round's last padded, all in one program. The
      solver is vmapped: each row of a call is computed at every iteration of its loop, which runs until the call's
      slowest row converges. A further round of a few cases padded to every case's rows (a first round of 10^4
      cases in one call) would then cost a whole first round; in calls of the block it costs the calls that hold
      it (docs/devices.md, "What each batched call does there")."""
    if plan.cpu:
        return min(fit_rows, ROWS_PER_CALL) if refits else None
    return min(max(fit_rows, refits), ROWS_PER_CALL_ELSEWHERE * devices)


def run_rows(problem, solver, max_iter, inputs, values, sigmas, lo, hi, pm, pw, z0, smoothing, dtype, starts,
             block=None, devices=None):
    """Fit B cases x S starts. inputs: stacked CaseInputs [B]; values, sigmas (B, m); lo, hi, pm, pw
    (B, n); z0 (B, S, n). The B x S rows go to the solver in calls of ``block`` rows (default: one call of
    them all), the last padded: a row's fit does not depend on the others in its call. devices: where the
    rows are solved (default ``jax.local_devices()``, this process's devices): over several, each call's
    rows are split among them (a 1-D mesh; ``block`` rounded up to a multiple of their number). Returns
    ``RowFits`` of NumPy arrays shaped (B, S, ...)."""
    devices = tuple(jax.local_devices() if devices is None else devices)
    B = np.asarray(values).shape[0]
    rows = B * starts
    block = -(-(block or rows) // len(devices)) * len(devices)
    total = -(-rows // block) * block

    def padded(a, per_case=True):  # (B, ...) per case, or (B * S, ...) per row -> (total, ...)
        a = np.asarray(a, np.float64)
        a = np.repeat(a, starts, axis=0) if per_case else a
        return np.concatenate([a, np.repeat(a[-1:], total - rows, axis=0)]) if total > rows else a

    args = [jax.tree_util.tree_map(padded, inputs)] + [padded(a) for a in (values, sigmas, lo, hi, pm, pw)]
    args.append(padded(np.asarray(z0).reshape(rows, -1), per_case=False))
    place = row_placement(devices)
    smoothing = jax.device_put(jnp.asarray(smoothing, dtype), place.replicated)
    # up to ``IN_FLIGHT`` calls are dispatched ahead of the one whose results are read: the host puts the next
    # call's rows on the devices while they compute, and the devices hold a few calls' rows, not a whole round's
    pending, parts, fit_rows = collections.deque(), [], solver_for(block, devices)
    for start in range(0, total, block):
        part = jax.tree_util.tree_map(lambda a: jax.device_put(np.asarray(a[start:start + block], dtype), place.rows),
                                      args)
        pending.append(fit_rows(problem, solver, max_iter, *part, smoothing))
        if len(pending) > IN_FLIGHT:
            parts.append(RowFits(*jax.device_get(pending.popleft())))
    parts += [RowFits(*out) for out in jax.device_get(list(pending))]
    return RowFits(*(np.concatenate(part)[:rows].reshape(B, starts, *part[0].shape[1:]) for part in zip(*parts)))

