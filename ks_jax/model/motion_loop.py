"""The loops that run a vehicle's steps (``motion``) from a start: to rest, to a time limit, or every step with
its path (docs/model.md, "Motion to rest").

``drive`` runs any step function (one vehicle's ``motion`` step, or the watched step of several vehicles in
``interaction``): forward-only, in a ``lax.while_loop`` that stops once nothing moves; every step, in a
``lax.scan``, where a path is kept; or every step in a checkpointed scan, where reverse mode is to pass
(``motion.step_function(reverse=True)``: the step with its hand-written adjoint). ``to_rest`` is one vehicle's
motion to rest through it.

Everything here is pure and unbatched: jit, vmap and differentiate at the edge.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from . import linalg as la
from .motion import (TIME_LIMIT, TIME_STEP, Carry, Chassis, Planar, RestResult, Wheels, body, start_carry,
                     step_function)


def steps_for(time_limit: float, dt: float) -> int:
    """The number of steps that reach ``time_limit`` at step ``dt`` (static)."""
    return max(1, math.ceil(time_limit / dt - 1e-9))


WHILE_CHUNK = 25  # steps between two tests of "all at rest" in the forward-only loop


def drive(advance, carry, n: int, moving, *, sample=None, reverse: bool = False):
    """Run ``advance`` (carry -> carry, one step) up to ``n`` times (static) from ``carry``: (the final carry, the
    stacked ``sample(carry)`` after every step, or None).

    With ``sample``, every step runs (``lax.scan``). Otherwise, with ``reverse`` False, the steps run in a
    ``lax.while_loop`` that stops once ``moving(carry)`` is False (under ``jax.vmap``: for every row), tested every
    ``WHILE_CHUNK`` steps, and then runs the steps left to ``n``: ``advance`` must leave a carry that is no longer
    moving unchanged. ``reverse`` True runs every step in a ``lax.scan`` cut into about sqrt(n) chunks, each
    recomputed in the backward pass (``jax.checkpoint``)."""

    def one(c, _):
        c = advance(c)
        return c, (None if sample is None else sample(c))

    def steps(c, count):
        return jax.lax.scan(one, c, None, length=count)[0]

    if sample is not None:
        return jax.lax.scan(one, carry, None, length=n)
    if not reverse:
        count, rest = divmod(n, WHILE_CHUNK)
        _, final = jax.lax.while_loop(lambda kc: (kc[0] < count) & moving(kc[1]),
                                      lambda kc: (kc[0] + 1, steps(kc[1], WHILE_CHUNK)), (0, carry))
    else:
        chunk = max(1, round(math.sqrt(n)))
        count, rest = divmod(n, chunk)
        final, _ = jax.lax.scan(jax.checkpoint(lambda c, _: (steps(c, chunk), None)), carry, None, length=count)
    if rest:  # the steps left to the limit (a vehicle at rest stays so)
        final = steps(final, rest)
    return final, None


def path_sample(c: Carry):
    """(4,) what a path keeps of a step: time s, x m, y m, yaw rad."""
    return jnp.stack([c.time, c.state.position[0], c.state.position[1], c.state.yaw])


def rest_result(start: Planar, final: Carry, samples=None) -> RestResult:
    """The ``RestResult`` of a motion from ``start`` that ended with ``final``; ``samples`` (n, 4): the path after
    every step (``path_sample``), to which the start is prepended, or None."""
    if samples is not None:
        first = jnp.stack([jnp.zeros_like(start.yaw), start.position[0], start.position[1], start.yaw])
        samples = jnp.concatenate([first[None], samples], axis=0)
    end = final.state
    return RestResult(end.position, la.degrees_0_360(la.safe_atan2(*la.sincos(end.yaw))),
                      jnp.degrees(end.yaw - start.yaw), final.time, final.distance, final.moving < 1.0, samples)


def to_rest(mass, izz, cg_height, chassis: Chassis, wheels: Wheels, friction, start: Planar, *,
            dt: float = TIME_STEP, time_limit: float = TIME_LIMIT, path: bool = False,
            reverse: bool = False) -> RestResult:
    """A vehicle's motion from ``start`` to rest (``RestResult``).

    ``dt``, ``time_limit`` (s), ``path`` and ``reverse`` are static. ``path``: keep the state after every step
    (the result's ``path``; for a picture: a sweep or a fit keeps none).

    Without a path, and ``reverse`` False, the steps run in a ``lax.while_loop`` that ends when the vehicle
    (under ``jax.vmap``: every vehicle of the batch) is at rest, or at the time limit: values and forward-mode
    derivatives (``jax.jvp``, ``jax.jacfwd``, as the fit uses) of a motion that stops early cost only its
    steps. Reverse-mode differentiation (``jax.grad``, ``jax.vjp``) cannot pass a while loop: ``reverse`` True
    runs every step to the limit in a ``lax.scan`` cut into chunks, each recomputed in the backward pass
    (``jax.checkpoint``), so that a gradient stores about 2 sqrt(n) states instead of n; its steps carry a
    hand-written adjoint (``_step_reverse``): first-order reverse mode only (``drive``)."""
    b = body(mass, izz, cg_height, chassis, wheels, friction, dt)
    advance = step_function(reverse and not path)
    final, samples = drive(lambda c: advance(b, c, dt), start_carry(start), steps_for(time_limit, dt),
                           lambda c: c.moving >= 1.0, sample=path_sample if path else None, reverse=reverse)
    return rest_result(start, final, samples)
