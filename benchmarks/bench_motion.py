"""Benchmark: the motion to rest of many vehicles at once, and its gradient.

    .venv/bin/python benchmarks/bench_motion.py [--pairs 100000] [--seconds 3] [--repeats 3]

Two-vehicle motions: ``pairs`` pairs of cars (2 x pairs vehicles) with random speeds after an impact (8-25 m/s in
any direction), yaw rates (-3..3 rad/s), brake fractions (0-1 per wheel) and steer (+-5 deg) on a road of friction
0.5-0.9, moved for ``seconds`` of motion at the default step (``model.motion.TIME_STEP``), float64, on this
machine's default device. Each variant runs through ``batch.stages.in_blocks`` (256 vehicles per block on a CPU),
as a case's pipeline runs it:

- forward, every step: ``to_rest(..., reverse=True)``, the scan that runs every step to the limit;
- forward, stopping at rest: the default ``lax.while_loop``, which stops once every vehicle of a block rests;
- gradient: ``jax.grad`` of the sum of every rest position over the batch with respect to every vehicle's speed,
  yaw rate and road friction (reverse mode through the checkpointed scan, whose steps carry the hand-written
  adjoint ``motion._step_reverse``), beside the forward of the same scan;
- for comparison, the same gradient through the same checkpointed scan of ``motion._step``, whose adjoint is
  JAX's own.

Reported: medians of ``repeats`` rounds (each variant once per round), the rate in vehicle-steps per second
(vehicles x steps / time; "stopping at rest" counts the steps to the limit, as the others), and gradient / forward
as the median of the per-round ratios. The goal on a 2-core CPU: 10^5 pairs for 3 s in under 10 s, gradient /
forward at most 4.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import statistics
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

from ks_jax.batch.stages import BLOCK_ROWS, in_blocks
from ks_jax.model import motion as M
from ks_jax.model import motion_loop as ML


def vehicles(n, seed=0):
    """n random vehicles just after an impact: (mass, izz, cg_height, chassis, wheels, friction, start)."""
    rng = np.random.default_rng(seed)
    u = lambda lo, hi, *shape: jnp.asarray(rng.uniform(lo, hi, (n, *shape)))  # noqa: E731
    speed, course = u(8.0, 25.0), u(-np.pi, np.pi)
    start = M.Planar(jnp.zeros((n, 2)), u(-np.pi, np.pi), jnp.stack([speed * jnp.cos(course),
                                                                     speed * jnp.sin(course)], -1), u(-3.0, 3.0))
    wheelbase = u(2.5, 3.1)
    chassis = M.Chassis(wheelbase, u(1.45, 1.7), wheelbase * u(0.4, 0.55))
    wheels = M.Wheels(u(0.0, 1.0, 4), u(-0.09, 0.09), u(0.01, 0.02))
    return u(1100.0, 2400.0), u(1500.0, 4500.0), u(0.45, 0.7), chassis, wheels, u(0.5, 0.9), start


def programs(seconds):
    def rows(reverse):
        def one(mass, izz, h, chassis, wheels, mu, start):
            return ML.to_rest(mass, izz, h, chassis, wheels, mu, start, time_limit=seconds, reverse=reverse)
        batched = jax.vmap(one)
        return in_blocks(batched, BLOCK_ROWS, (0,) * 7) if jax.default_backend() == "cpu" else batched

    def own_adjoint(mass, izz, h, chassis, wheels, mu, start):
        """The rest position through ``to_rest(reverse=True)``'s checkpointed chunks, of steps that JAX
        differentiates by its own rules."""
        n = ML.steps_for(seconds, M.TIME_STEP)
        chunk = max(1, round(math.sqrt(n)))
        b = M.body(mass, izz, h, chassis, wheels, mu, M.TIME_STEP)
        carry = M.start_carry(start)
        steps = lambda c, k: jax.lax.scan(lambda c, _: (M._step(b, c, M.TIME_STEP), None), c, None, length=k)[0]  # noqa: E731
        carry = jax.lax.scan(jax.checkpoint(lambda c, _: (steps(c, chunk), None)), carry, None, length=n // chunk)[0]
        return M.RestResult(steps(carry, n % chunk).state.position, *(None,) * 5)

    every, stopping = rows(True), rows(False)
    own = jax.vmap(own_adjoint)
    own = in_blocks(own, BLOCK_ROWS, (0,) * 7) if jax.default_backend() == "cpu" else own

    def total(motion):
        def f(speed_scale, yaw_rate, mu, args):
            mass, izz, h, chassis, wheels, _, start = args
            start = start._replace(velocity=start.velocity * speed_scale[:, None], yaw_rate=yaw_rate)
            return jnp.sum(motion(mass, izz, h, chassis, wheels, mu, start).rest_position)
        return jax.jit(jax.grad(f, argnums=(0, 1, 2)))

    forward = jax.jit(lambda *a: every(*a).rest_position)
    early = jax.jit(lambda *a: stopping(*a).rest_position)
    return forward, early, total(every), total(own)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=100_000)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    n = 2 * args.pairs
    steps = ML.steps_for(args.seconds, M.TIME_STEP)
    data = vehicles(n)
    forward, early, grad, own = programs(args.seconds)
    ones = jnp.ones(n)
    calls = {
        "forward, every step": lambda: forward(*data),
        "forward, stopping at rest": lambda: early(*data),
        "gradient (reverse mode)": lambda: grad(ones, data[-1].yaw_rate, data[5], data),
        "gradient, JAX's own adjoint": lambda: own(ones, data[-1].yaw_rate, data[5], data),
    }
    compile_s = {}
    for name, call in calls.items():
        t = time.perf_counter()
        jax.block_until_ready(call())
        compile_s[name] = time.perf_counter() - t
    times = {name: [] for name in calls}
    for _ in range(args.repeats):
        for name, call in calls.items():
            t = time.perf_counter()
            jax.block_until_ready(call())
            times[name].append(time.perf_counter() - t)
    ratios = {name: [g / f for g, f in zip(times[name], times["forward, every step"])]
              for name in ("gradient (reverse mode)", "gradient, JAX's own adjoint")}
    print(f"bench_motion: {args.pairs} two-vehicle motions ({n} vehicles), {args.seconds:g} s of motion at "
          f"{M.TIME_STEP * 1000:g} ms ({steps} steps), float64")
    print(f"  {datetime.date.today()}, {platform.node()}, {jax.devices()[0].device_kind}, {os.cpu_count()} CPUs, "
          f"jax {jax.__version__}; {' '.join([os.path.basename(sys.argv[0])] + (argv or sys.argv[1:]))}")
    for name, ts in times.items():
        med = statistics.median(ts)
        print(f"  {name:28s} {med:8.3f} s  {n * steps / med:10.3g} vehicle-steps/s   (first call "
              f"{compile_s[name]:.2f} s)")
    hand, theirs = calls["gradient (reverse mode)"](), calls["gradient, JAX's own adjoint"]()
    differ = max(float(jnp.max(jnp.abs(x - y)) / jnp.max(jnp.abs(y))) for x, y in zip(hand, theirs))
    print(f"  the two gradients differ by at most {differ:.1e} of their largest entry")
    for name, rs in ratios.items():
        print(f"  {name} / forward (every step): {statistics.median(rs):.2f} (median of {len(rs)} rounds)")


if __name__ == "__main__":
    main()
