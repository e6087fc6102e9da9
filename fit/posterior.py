"""The posterior of a reconstruction's unknowns by NUTS (docs/fit.md, "Posterior"; ``reconstruct(posterior=N)``,
``ks-jax fit --posterior N``).

The density, in the fit's unconstrained coordinates z (``problem.to_x``): the evidence's Gaussian likelihood
through the smooth engine, exp(-|r|^2 / 2) with r the whitened residuals of the fit (evidence in sigmas, then
the Gaussian priors where given), uniform priors within the bounds, and the log-Jacobian of the bound transform,
so that the draws, mapped back to x, follow the posterior in the physical unknowns.

NUTS is BlackJAX's (the ``posterior`` extra): a library of samplers over a log-density that the caller writes,
which is what the fit already has; its kernels are pure functions that jit and vmap, so the chains run side by
side in one compiled program (on several devices, split among them), each with its own window adaptation of
step size and diagonal mass matrix. NumPyro's NUTS would need the density rewritten as a model of sample sites.

Each chain starts at the fit's estimate, moved by a small random step (a tenth of a unit in z) so that the
chains' agreement (R-hat) means something. Reported per unknown (SI): mean, std, the 2.5, 16, 50, 84 and 97.5%
quantiles, Gelman and Rubin's potential scale reduction (R-hat, over whole chains) and the effective sample size
(BlackJAX's diagnostics), and the divergent transitions of all chains; a warning where R-hat exceeds 1.01, the
effective sample size is below 100 per chain, or any transition diverged. R-hat compares chains, so with one chain
it is undefined (NaN; null in JSON) and a warning says why; the effective sample size is computed for one chain
as for several.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass, field
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ks_jax.backend import checked_devices, row_placement
from ks_jax.compilation import quick_jit
from ks_jax.progress import PROGRESS_DELAY, Progress

from .arrays import FitArrays
from .problem import Problem, to_x
from .rows import Row, whitened

QUANTILES = {"q025": 2.5, "q16": 16.0, "q50": 50.0, "q84": 84.0, "q975": 97.5}
RHAT_LIMIT = 1.01  # above: the chains disagree
ESS_PER_CHAIN = 100  # below this many effective draws per chain: too few for the tails' quantiles
START_JITTER = 0.1  # the chains' starts about the estimate, in z
TARGET_ACCEPTANCE = 0.8  # the warmup's default aim for NUTS's mean acceptance (Stan's)
SEGMENT = 100  # transitions per compiled call of the sampler, between which its progress is shown
MISSING = "the posterior needs BlackJAX (the 'posterior' extra): pip install 'ks-jax[posterior]'"


def sampler():
    """BlackJAX, imported when a posterior is first drawn, not with ``fit``: importing it starts JAX's backend,
    which a program of several processes must not have started before ``jax.distributed.initialize``
    (docs/devices.md). ImportError naming the extra where it is not installed."""
    try:
        return importlib.import_module("blackjax")
    except ImportError as err:
        raise ImportError(MISSING) from err


@dataclass
class Posterior:
    """NUTS draws of a fit's unknowns. ``samples``: (chains, draws, n) SI, columns in the order of ``paths``;
    ``summary``: path -> {"mean", "std", "q025", "q16", "q50", "q84", "q975", "rhat", "ess"} (SI);
    ``divergences``: divergent transitions, all chains; ``warnings``: what makes the draws doubtful;
    ``target_acceptance``: the mean acceptance the warmup tuned each chain's step size toward."""

    paths: list
    chains: int
    draws: int
    warmup: int
    seed: int
    samples: np.ndarray = field(repr=False)
    summary: dict
    divergences: int
    step_size: list
    warnings: list
    target_acceptance: float = TARGET_ACCEPTANCE

    def to_dict(self) -> dict:
        """JSON-ready: per unknown its summary (SI; a non-finite value as null), and the run's settings."""
        num = lambda v: float(v) if np.isfinite(v) else None  # noqa: E731
        return {"chains": self.chains, "draws": self.draws, "warmup": self.warmup, "seed": self.seed,
                "target_acceptance": self.target_acceptance, "divergences": self.divergences,
                "warnings": list(self.warnings),
                "unknowns": {p: {k: num(v) for k, v in s.items()} for p, s in self.summary.items()}}


def log_density(problem: Problem, z, d, smoothing):
    """The posterior's log-density (up to a constant) at the unconstrained unknowns z (n,) of one row ``d``
    (``rows.whitened``): -|r|^2 / 2 plus log |dx/dz|; -inf where it is not finite (no exchange can be
    computed there)."""
    r, _ = whitened(problem, z, d, smoothing)
    dxdz = jax.jvp(lambda q: to_x(q, d.lo, d.hi), (z,), (jnp.ones_like(z),))[1]
    value = -0.5 * jnp.sum(r * r) + jnp.sum(jnp.log(dxdz))
    return jnp.where(jnp.isfinite(value), value, -jnp.inf)


@partial(jax.jit, static_argnums=0)
def _value_and_gradient(problem: Problem, z, d, smoothing):
    """``log_density`` and its gradient in z. By reverse mode, except where the evidence holds the motion to rest:
    there by forward mode, one tangent per unknown (a posterior has a few), so that each vehicle's steps run in the
    motion's while loop and end when it rests. Reverse mode would need the reverse-ready scan, which runs every
    step to the time limit and keeps them all: a motion that rests in 2 s of a 10 s limit costs five times the
    steps, with every NUTS leapfrog taking a gradient."""
    if problem.motion is None:
        return jax.value_and_grad(log_density, argnums=1)(problem, z, d, smoothing)

    def along(tangent):
        return jax.jvp(lambda q: log_density(problem, q, d, smoothing), (z,), (tangent,))

    values, gradient = jax.vmap(along)(jnp.eye(z.shape[0], dtype=z.dtype))
    return values[0], gradient


@partial(jax.custom_vjp, nondiff_argnums=(0,))
def _density(problem: Problem, z, d, smoothing):
    """``log_density`` for the sampler, whose gradient is one jitted function: NUTS takes it at several places
    of its transition, and each would otherwise trace (and batch over the chains) the engine's reverse pass
    anew; a jitted function is traced once per program."""
    return _value_and_gradient(problem, z, d, smoothing)[0]


def _density_fwd(problem, z, d, smoothing):
    value, gradient = _value_and_gradient(problem, z, d, smoothing)
    return value, (gradient, d, smoothing)


def _density_bwd(problem, saved, cotangent):
    gradient, d, smoothing = saved
    return cotangent * gradient, jax.tree_util.tree_map(jnp.zeros_like, d), jnp.zeros_like(smoothing)


_density.defvjp(_density_fwd, _density_bwd)


class _Tuning(NamedTuple):
    """One chain's adaptation (Stan's windows): the step size's dual averaging, the mass matrix's running
    variance, and the step size and inverse mass matrix that its next transition uses."""

    averaging: tuple
    variance: tuple
    step_size: jax.Array
    inverse_mass: jax.Array


def _tuned(blackjax, target, tuning: _Tuning, slow, window_end, last, position, acceptance) -> _Tuning:
    """``tuning`` after one warmup transition (``acceptance``, now at ``position``), as Stan's window adaptation
    has it: the step size follows the acceptance rate toward ``target`` by dual averaging throughout; in a slow
    window the mass matrix's variance gathers the positions, and at the window's end becomes the new inverse mass
    matrix while the averaging restarts from its mean step size; after the ``last`` warmup transition the step size
    is the averaging's mean."""
    da_init, da_update, da_final = blackjax.adaptation.step_size.dual_averaging_adaptation(target)
    _, mm_update, mm_final = blackjax.adaptation.mass_matrix.mass_matrix_adaptation(is_diagonal_matrix=True)
    pick = lambda flag, a, b: jax.tree_util.tree_map(lambda u, v: jnp.where(flag, u, v), a, b)  # noqa: E731
    averaging = da_update(tuning.averaging, acceptance)
    variance = pick(slow, mm_update(tuning.variance, position), tuning.variance)
    closed = mm_final(variance)
    variance = pick(window_end, closed, variance)
    averaging = pick(window_end, da_init(da_final(averaging)), averaging)
    inverse_mass = jnp.where(window_end, closed.inverse_mass_matrix, tuning.inverse_mass)
    step_size = jnp.where(last, jnp.exp(averaging.log_step_size_avg), jnp.exp(averaging.log_step_size))
    return _Tuning(averaging, variance, step_size, inverse_mass)


def _pieces(blackjax, density, target=TARGET_ACCEPTANCE):
    """A chain's first carry (its NUTS state at ``start`` and its untuned adaptation) and the step of its scan:
    one NUTS transition at the carried step size and mass matrix, then (while ``adapting``) Stan's adaptation
    of them toward the mean acceptance ``target`` (``_tuned``; a number or a traced scalar). The step's inputs per
    transition: (key, slow, window_end, last, adapting)."""
    transition = blackjax.nuts.build_kernel()
    da_init = blackjax.adaptation.step_size.dual_averaging_adaptation(target)[0]
    mm_init = blackjax.adaptation.mass_matrix.mass_matrix_adaptation(is_diagonal_matrix=True)[0]

    def first(start):
        variance = mm_init(start.shape[0])
        tuning = _Tuning(da_init(jnp.asarray(1.0, start.dtype)), variance, jnp.asarray(1.0, start.dtype),
                         variance.inverse_mass_matrix.astype(start.dtype))
        return blackjax.nuts.init(start, density), tuning

    def step(carry, xs):
        state, tuning = carry
        key, slow, window_end, last, adapting = xs
        state, info = transition(key, state, density, tuning.step_size, tuning.inverse_mass)
        after = _tuned(blackjax, target, tuning, slow, window_end, last, state.position, info.acceptance_rate)
        tuning = jax.tree_util.tree_map(lambda a, b: jnp.where(adapting, a, b), after, tuning)
        return (state, tuning), (state.position, info.is_divergent)

    return first, step


def _schedule(blackjax, warmup: int, steps: int):
    """Per transition (``steps`` of them, the warmup's first): whether it is in a slow window, ends one, is the
    warmup's last, and adapts. NumPy bool arrays (steps,)."""
    flags = np.zeros((4, steps), bool)
    if warmup:
        with jax.ensure_compile_time_eval():
            flags[:2, :warmup] = np.asarray(blackjax.adaptation.window_adaptation.build_schedule(warmup), bool).T
        flags[2, warmup - 1] = True
        flags[3, :warmup] = True
    return tuple(flags)


def _step_keys(key, warmup: int, draws: int, steps: int):
    """A chain's key per transition: the warmup's from the first half of ``key``, the draws' from the second (as
    BlackJAX's ``window_adaptation`` and a NUTS scan would take them), the last repeated up to ``steps``."""
    adapt_key, draw_key = jax.random.split(key)
    keys = jnp.concatenate([jax.random.split(adapt_key, warmup), jax.random.split(draw_key, draws)])
    return jnp.concatenate([keys, jnp.repeat(keys[-1:], steps - warmup - draws, axis=0)])


def run_chains(density, keys, z0, draws: int, warmup: int, target_acceptance=TARGET_ACCEPTANCE):
    """NUTS chains of ``density`` (z (n,) -> log-density), one per key (keys (C,), starts z0 (C, n)), each
    adapted for ``warmup`` transitions by Stan's window adaptation, then ``draws`` draws: the draws
    (C, draws, n), their divergences (C, draws) and each chain's step size (C,).

    Each chain's adaptation and draws are one scan of one NUTS transition, its step size and mass matrix
    carried along (fixed once the warmup ends), so that the transition, with the density's gradient inside,
    is traced and compiled once. The draws are those of BlackJAX's ``window_adaptation`` run on the chain's
    first key and a NUTS scan on its second (whose target acceptance is 0.8, the default here). ``sample`` runs
    the same scan in segments."""
    blackjax = sampler()
    first, step = _pieces(blackjax, density, target_acceptance)
    flags = _schedule(blackjax, warmup, warmup + draws)

    def chain(key, start):
        xs = (_step_keys(key, warmup, draws, warmup + draws), *map(jnp.asarray, flags))
        (_, tuning), (zs, divergent) = jax.lax.scan(step, first(start), xs)
        return zs[warmup:], divergent[warmup:], tuning.step_size

    return jax.vmap(chain)(keys, z0)


@partial(quick_jit, static_argnames=("problem",))
def _segment(problem: Problem, d, smoothing, target, carry, z0, begin, keys, flags):
    """Every chain's next transitions (keys (C, S), flags: four (S,) of ``_schedule``) from ``carry``, or where
    ``begin`` from each chain's first carry at z0 (C, n), the warmup aiming at the mean acceptance ``target``: the
    carry after them, and their draws (C, S, n) in z and divergences (C, S). The program of a posterior, one for all
    its segments and targets: most of its first call is compiling it."""
    first, step = _pieces(sampler(), lambda z: _density(problem, z, d, smoothing), target)
    carry = jax.lax.cond(begin, lambda _: jax.vmap(first)(z0), lambda c: c, carry)
    return jax.vmap(lambda c, k: jax.lax.scan(step, c, (k, *flags)))(carry, keys)


def _no_carry(problem: Problem, d, smoothing, z0):
    """Zeros shaped as every chain's carry: what ``_segment`` is given with ``begin``."""
    first, _ = _pieces(sampler(), lambda z: _density(problem, z, d, smoothing))
    shapes = jax.eval_shape(jax.vmap(first), z0)
    return jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes)


def sample(problem: Problem, row: FitArrays, z_best, *, draws: int, chains: int = 4, warmup: int | None = None,
           seed: int = 0, smoothing: float = 1e-3, dtype=None, devices=None, offset=None,
           progress: bool = False, target_acceptance: float = TARGET_ACCEPTANCE) -> Posterior:
    """``draws`` NUTS draws per chain from the posterior of one fit's unknowns (the module's docstring).

    row: the fit's arrays of one case (``FitArrays.row``); z_best (n,): its
    estimate in z. warmup: adaptation steps per chain (default ``draws``). devices: where the chains run (default
    this process's; over several, the chains are split among them where their count divides evenly). offset (n,):
    added to the draws (a scene fitted about its own origin: ``FitArrays.x_offset``). progress: a bar (stderr)
    once the draws have taken ``PROGRESS_DELAY`` s: they run in compiled segments of ``SEGMENT`` transitions.
    target_acceptance: the mean acceptance the warmup tunes the step size toward, in (0, 1): higher, smaller
    steps, fewer divergences where the density bends sharply (at a bound), more gradients per draw."""
    sampler()
    if draws < 1 or chains < 1:
        raise ValueError(f"posterior: draws = {draws}, chains = {chains}: need at least one of each")
    warmup = draws if warmup is None else int(warmup)
    dtype = dtype or jnp.result_type(float)
    devices = checked_devices(devices, "posterior")
    rng = np.random.default_rng(seed)
    n = len(problem.unknowns)
    z0 = np.asarray(z_best, np.float64)[None] + START_JITTER * rng.standard_normal((chains, n))
    keys = jax.random.split(jax.random.key(seed), chains)
    d = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype),
                               Row(row.inputs, row.values, row.sigmas, row.lo, row.hi, row.pm, row.pw))
    z0 = jnp.asarray(z0, dtype)
    if len(devices) > 1 and chains % len(devices) == 0:
        place = row_placement(devices)
        keys, z0 = jax.device_put(keys, place.rows), jax.device_put(z0, place.rows)
    smoothing, target = jnp.asarray(smoothing, dtype), jnp.asarray(target_acceptance, dtype)
    steps = warmup + draws
    segment = min(SEGMENT, steps)
    total = -(-steps // segment) * segment  # padded: the transitions after the last draw are not kept
    flags = _schedule(sampler(), warmup, total)
    step_keys = jax.vmap(partial(_step_keys, warmup=warmup, draws=draws, steps=total))(keys)
    carry = _no_carry(problem, d, smoothing, z0)
    bar = Progress(steps, "ks-jax posterior", "step", progress, PROGRESS_DELAY)
    parts = []
    for lo in range(0, total, segment):
        carry, part = _segment(problem, d, smoothing, target, carry, z0, lo == 0, step_keys[:, lo:lo + segment],
                               tuple(jnp.asarray(f[lo:lo + segment]) for f in flags))
        parts.append(jax.tree_util.tree_map(np.asarray, part))
        bar.update(min(segment, steps - lo))
    bar.close()
    zs, divergent = (np.concatenate(a, axis=1)[:, warmup:steps] for a in zip(*parts))
    step_size = carry[1].step_size
    x = np.asarray(jax.vmap(jax.vmap(lambda z: to_x(z, d.lo, d.hi)))(zs), np.float64)
    x = x + (0.0 if offset is None else np.asarray(offset, np.float64))
    return summarize(list(problem.unknowns), x, int(np.sum(np.asarray(divergent))), warmup, seed,
                     [float(s) for s in np.asarray(step_size)], float(target_acceptance))


RHAT_UNDEFINED = ("R-hat is undefined: R-hat needs two or more chains, and with one the draws cannot show whether "
                  "chains agree (a mode the chain never reached goes unseen); run two chains or more")
RHAT_ONE_DRAW = "R-hat is undefined: R-hat needs two or more draws per chain"
ESS_UNDEFINED = "the effective sample size is undefined: it needs two or more draws per chain"
SPREAD = ("std", "q025", "q16", "q50", "q84", "q975", "ess")  # what a chain that never moved cannot measure


@jax.jit
def _diagnostics(x):
    """BlackJAX's potential scale reduction (R-hat) and effective sample size of every unknown of draws x (chains,
    draws, n), each (n,), as one compiled program: run op by op they compile many small programs of their own.
    BlackJAX squeezes away every axis of length 1, an unknown's too: shaped back here. R-hat needs two chains and
    two draws, the effective sample size two draws (BlackJAX asserts otherwise): NaN where not defined."""
    diagnostics = importlib.import_module("blackjax.diagnostics")
    chains, draws, n = x.shape
    nan = jnp.full((n,), jnp.nan, x.dtype)
    rhat = jnp.reshape(diagnostics.potential_scale_reduction(x), (n,)) if chains > 1 and draws > 1 else nan
    ess = jnp.reshape(diagnostics.effective_sample_size(x), (n,)) if draws > 1 else nan
    return rhat, ess


def _chains(indices) -> str:
    """'chain 2', 'chains 1 and 3' (1-based, as the panel counts them)."""
    k = [str(i + 1) for i in indices]
    return f"chain {k[0]}" if len(k) == 1 else f"chains {', '.join(k[:-1])} and {k[-1]}"


def summarize(paths, x, divergences: int, warmup: int, seed: int, step_size,
              target_acceptance: float = TARGET_ACCEPTANCE) -> Posterior:
    """The ``Posterior`` of draws ``x`` (chains, draws, n), SI: moments, quantiles, R-hat and effective sample
    size per unknown (NaN where undefined: R-hat with one chain or one draw, the effective sample size with one
    draw, each with a warning that says why), and the warnings they call for."""
    chains, draws, _ = x.shape
    rhat, ess = (np.asarray(a, np.float64) for a in _diagnostics(jnp.asarray(x, jnp.float64)))
    flat = x.reshape(chains * draws, -1)
    q = {k: np.percentile(flat, v, axis=0) for k, v in QUANTILES.items()}
    summary = {p: {"mean": float(flat[:, j].mean()), "std": float(flat[:, j].std(ddof=1)) if len(flat) > 1 else 0.0,
                   **{k: float(v[j]) for k, v in q.items()}, "rhat": float(rhat[j]), "ess": float(ess[j])}
               for j, p in enumerate(paths)}
    warnings = []
    # a chain that never moved (every draw the same: the sampler refused every step, too few adaptation steps or a
    # density it cannot follow) measures no spread; where no chain moved, the spread is not reported at all
    still = np.ptp(x, axis=1) == 0 if draws > 1 else np.zeros((chains, len(paths)), bool)
    stuck = [j for j in range(len(paths)) if still[:, j].any()]
    for j in stuck:
        if still[:, j].all():
            summary[paths[j]].update({k: math.nan for k in SPREAD})
    if chains * draws == 1:  # one draw in all: no spread either
        for s in summary.values():
            s.update({k: math.nan for k in SPREAD})
        warnings.append("one draw in all measures no spread: the std, quantiles and ESS are undefined; draw more")
    if stuck:
        which = [f"{paths[j]} ({'every chain' if still[:, j].all() else _chains(np.flatnonzero(still[:, j]))})"
                 for j in stuck]
        warnings.append(f"a chain never moved: {', '.join(which)}: every draw of it is the same, so it measures no "
                        "spread (the std, quantiles and ESS of an unknown no chain moved in are undefined); draw "
                        "more, with more adaptation steps, or run more chains")
    poor = [f"{p} ({s['rhat']:.3f})" for p, s in summary.items() if s["rhat"] > RHAT_LIMIT]
    if poor:
        warnings.append(f"R-hat above {RHAT_LIMIT}: {', '.join(poor)}: the chains disagree (several modes, or "
                        "too few draws); draw more, and read the quantiles as doubtful")
    few = [f"{p} ({s['ess']:.0f})" for p, s in summary.items() if s["ess"] < ESS_PER_CHAIN * chains]
    if few:
        warnings.append(f"effective sample size below {ESS_PER_CHAIN} per chain: {', '.join(few)}: the 2.5% and "
                        "97.5% quantiles are rough; draw more")
    if chains < 2:
        warnings.append(RHAT_UNDEFINED)
    elif draws < 2:
        warnings.append(RHAT_ONE_DRAW)
    if draws < 2:
        warnings.append(ESS_UNDEFINED)
    if divergences:
        warnings.append(f"{divergences} divergent transition{'s' * (divergences != 1)} of {chains * draws}: the "
                        "sampler could not follow the density everywhere (a sharp stick/slide edge, or a bound); "
                        "the draws may miss part of the posterior; a target acceptance nearer 1 than "
                        f"{target_acceptance:g} takes smaller steps, which follow it more closely")
    return Posterior(list(paths), chains, draws, warmup, seed, x, summary, divergences, list(step_size), warnings,
                     target_acceptance)
