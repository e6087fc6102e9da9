"""Benchmark: the motion to rest's gradient by the step's hand-written adjoint and by JAX's under checkpoint policies.

    .venv/bin/python benchmarks/bench_motion_adjoint.py [--pairs 100000] [--seconds 3] [--repeats 3]

The vehicles, batch, blocks and loss of ``bench_motion.py``: the gradient of the sum of every rest position over
the batch with respect to every vehicle's speed, yaw rate and road friction, in reverse mode through
``to_rest(reverse=True)``'s checkpointed chunks (``chunks``, the same scan). Variants, each one program:

- forward, every step: ``to_rest(..., reverse=True)``'s values;
- hand-written adjoint: the gradient as the library takes it, its steps carrying ``motion._step_reverse``;
- JAX's adjoint of the step under ``jax.checkpoint`` with ``save_only_these_names`` of the values that
  ``motion._advance`` names (``checkpoint_name``): ``costly`` its square roots, tanh, sine and cosine; ``as the
  hand adjoint`` every value the hand-written adjoint stores (``motion._Saved``); and ``jax.checkpoint`` with no
  policy (nothing saved: the step is computed again in the backward pass).

Reported: medians of ``repeats`` rounds (each variant once per round), gradient / forward as the median of the
per-round ratios, the largest difference of each gradient from the hand-written adjoint's (of the largest
entry), and the scratch memory of each program (XLA's ``memory_analysis().temp_size_in_bytes``).

Measured with ``--pairs 100000 --repeats 3`` (2026-11-29 02:23-02:49 UTC, 2 CPUs shared with other work, load
average 3.5 at the end, float64, jax 0.10.2): forward 11.6 s; the hand-written adjoint's gradient 38.6 s, 3.17 x
the forward; checkpoint, costly 92.5 s, 7.87 x; checkpoint, as the hand adjoint 76.7 s, 6.47 x; checkpoint, no
policy 104.3 s, 9.37 x. The gradients agree to 4e-10 of the largest entry; every gradient's program has 326 MiB of
scratch. JAX's adjoint under a checkpoint policy would replace the hand-written one if it came within 10% of its
ratio; none does (docs/performance.md, "Motion to rest").
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
from bench_motion import vehicles

from ks_jax.batch.stages import BLOCK_ROWS, in_blocks
from ks_jax.model import motion as M
from ks_jax.model import motion_loop as ML

COSTLY = ("motion.sincos", "motion.inv_locked", "motion.inv_rolling", "motion.inv_slip", "motion.tanh",
          "motion.speed", "motion.mean_speed")
AS_HAND = COSTLY + ("motion.wheel_velocities", "motion.loads", "motion.tyre_forces", "motion.force", "motion.dq",
                    "motion.raw", "motion.energy", "motion.phi", "motion.q_new", "motion.v_mean")


def chunks(step, seconds):
    """The rest position through ``to_rest(reverse=True)``'s scan in checkpointed chunks of ``step``."""
    def one(mass, izz, h, chassis, wheels, mu, start):
        n = ML.steps_for(seconds, M.TIME_STEP)
        chunk = max(1, round(math.sqrt(n)))
        b = M.body(mass, izz, h, chassis, wheels, mu, M.TIME_STEP)
        carry = M.start_carry(start)

        def steps(c, k):
            return jax.lax.scan(lambda c, _: (step(b, c, M.TIME_STEP), None), c, None, length=k)[0]

        carry = jax.lax.scan(jax.checkpoint(lambda c, _: (steps(c, chunk), None)), carry, None, length=n // chunk)[0]
        return steps(carry, n % chunk).state.position
    return one


def programs(seconds):
    def blocked(one):
        batched = jax.vmap(one)
        return in_blocks(batched, BLOCK_ROWS, (0,) * 7) if jax.default_backend() == "cpu" else batched

    def library(mass, izz, h, chassis, wheels, mu, start):
        return ML.to_rest(mass, izz, h, chassis, wheels, mu, start, time_limit=seconds, reverse=True).rest_position

    def total(motion):
        def f(speed_scale, yaw_rate, mu, args):
            mass, izz, h, chassis, wheels, _, start = args
            start = start._replace(velocity=start.velocity * speed_scale[:, None], yaw_rate=yaw_rate)
            return jnp.sum(motion(mass, izz, h, chassis, wheels, mu, start))
        return jax.grad(f, argnums=(0, 1, 2))

    names = jax.checkpoint_policies.save_only_these_names

    def remat(policy):
        return jax.checkpoint(M._step, policy=policy, static_argnums=(2,))

    def forward(speed_scale, yaw_rate, mu, args):
        return blocked(library)(*args)

    return {
        "forward, every step": forward,
        "hand-written adjoint": total(blocked(library)),
        "checkpoint, costly": total(blocked(chunks(remat(names(*COSTLY)), seconds))),
        "checkpoint, as the hand adjoint": total(blocked(chunks(remat(names(*AS_HAND)), seconds))),
        "checkpoint, no policy": total(blocked(chunks(remat(None), seconds))),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=100_000)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    n = 2 * args.pairs
    steps = ML.steps_for(args.seconds, M.TIME_STEP)
    data = vehicles(n)
    inputs = (jnp.ones(n), data[-1].yaw_rate, data[5], data)
    compiled, compile_s, memory = {}, {}, {}
    for name, fn in programs(args.seconds).items():
        t = time.perf_counter()
        compiled[name] = jax.jit(fn).lower(*inputs).compile()
        compile_s[name] = time.perf_counter() - t
        memory[name] = compiled[name].memory_analysis().temp_size_in_bytes
        jax.block_until_ready(compiled[name](*inputs))
    times = {name: [] for name in compiled}
    for _ in range(args.repeats):
        for name, call in compiled.items():
            t = time.perf_counter()
            jax.block_until_ready(call(*inputs))
            times[name].append(time.perf_counter() - t)
    forward = "forward, every step"
    print(f"bench_motion_adjoint: {args.pairs} two-vehicle motions ({n} vehicles), {args.seconds:g} s of motion at "
          f"{M.TIME_STEP * 1000:g} ms ({steps} steps), float64")
    print(f"  {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, {platform.node()}, "
          f"{jax.devices()[0].device_kind}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}, "
          f"jax {jax.__version__}; {' '.join([os.path.basename(sys.argv[0])] + (argv or sys.argv[1:]))}")
    hand = compiled["hand-written adjoint"](*inputs)
    for name, ts in times.items():
        ratio = statistics.median(g / f for g, f in zip(ts, times[forward]))
        line = (f"  {name:32s} {statistics.median(ts):8.3f} s  x{ratio:5.2f} forward  "
                f"scratch {memory[name] / 2**20:7.1f} MiB")
        if name != forward:
            grad = compiled[name](*inputs)
            differ = max(float(jnp.max(jnp.abs(x - y)) / jnp.max(jnp.abs(y))) for x, y in zip(grad, hand))
            line += f"  differs from the hand adjoint's by {differ:.1e}"
        print(line + f"  (compile {compile_s[name]:.1f} s)")


if __name__ == "__main__":
    main()
