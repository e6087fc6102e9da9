"""Benchmark: the watched motion after the first exchange (``model.interaction.interact``) against the motion to rest
of each vehicle alone.

    .venv/bin/python benchmarks/bench_interaction.py [--cases 10000] [--repeats 3] [--seconds 10] [--slots 8] \
        [--plan cpu|accelerator]

Two-vehicle cases, float64, random (seed 0): car 0 (1100-2000 kg) at 8-20 m/s along +x from (-5, 0) into car 1
(1100-2000 kg) at rest at (0, 0.8-2.2 m) turned 0.5-2.6 rad, restitution 0.05-0.3, friction 0.5 at the contact, on
roads of friction 0.6-0.9 with every wheel braked by 0.5-1 (rolling resistance 0.015): oblique impacts of which
some part after the first exchange and others meet again (side-slaps), up to ``slots`` exchanges each. The first
exchange (automatic contact, ``contact.automatic_exchange``) and the vehicles' states at its instant are computed
once, and then, from the same states, as the plan of the default device runs a case's motion (``--plan`` to choose):
on the CPU's path in blocks of 256 cases (``batch.stages.in_blocks``), each block's loop stopping once its cases are
at rest or at the time limit (``seconds``); on the accelerator's path all cases in one loop:

- watched: ``interact``: both vehicles move on, their pair is watched at every step and exchanges again where it
  overlaps and approaches;
- watched, packed: the same with the loop's state carried packed (``interact(packed=True)``, as an accelerator's path
  runs it: fewer copies and kernels a step on a GPU; on a CPU, more memory copied);
- alone: ``motion_loop.to_rest`` of each vehicle alone (watching turned off).

Reported: each variant's compile (XLA's default settings, as users get them; the first exchange's program, not
measured, with the quick ones), the median of ``repeats`` rounds after it (each variant once per round), the cases
per second, watched / alone and packed / watched as the medians of the rounds' ratios, the largest difference
between the packed and the plain rest positions, and how many exchanges the cases had.
"""

from __future__ import annotations

import argparse
import collections
import datetime
import functools
import os
import platform
import statistics
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

from ks_jax.backend import plan_for
from ks_jax.batch.stages import BLOCK_ROWS, in_blocks
from ks_jax.compilation import compiler_options
from ks_jax.model import motion as M
from ks_jax.model import motion_loop as ML
from ks_jax.model.contact import advance, automatic_exchange
from ks_jax.model.interaction import APPROACH_TOLERANCE, Bodies, Watch, interact
from ks_jax.model.types import Contact, State, Vehicle

LENGTH, WIDTH, HEIGHT = 4.5, 1.8, 1.4  # m, both cars; the CG in the middle of the box, at half its height
CHASSIS = M.Chassis(jnp.asarray(2.7), jnp.asarray(1.55), jnp.asarray(1.35))


def cases(n, seed=0):
    """n random cases: a dict of (n, ...) arrays (the module's docstring)."""
    rng = np.random.default_rng(seed)
    u = lambda lo, hi: rng.uniform(lo, hi, n)  # noqa: E731
    mass = np.stack([u(1100.0, 2000.0), u(1100.0, 2000.0)], -1)
    return {"mass": mass, "izz": mass * np.stack([u(1.5, 2.0), u(1.5, 2.0)], -1), "speed": u(8.0, 20.0),
            "offset": u(0.8, 2.2), "yaw": u(0.5, 2.6), "restitution": u(0.05, 0.3), "road": u(0.6, 0.9),
            "brake": u(0.5, 1.0)}


def _vehicle(mass, izz):
    return Vehicle(mass, jnp.diag(jnp.stack([0.2 * izz, 0.9 * izz, izz])), jnp.asarray(LENGTH), jnp.asarray(WIDTH),
                   jnp.asarray(HEIGHT), jnp.asarray(LENGTH / 2), jnp.asarray(HEIGHT / 2))


def _wheels(c):
    return M.Wheels(jnp.full(4, c["brake"]), jnp.zeros(()), jnp.asarray(0.015))


def prepare(c):
    """One case's first exchange and its inputs to both variants: (vehicles, start ``motion.Planar`` (2, ...) at the
    first exchange's instant with the velocities after it, the first ``ExchangeResult``)."""
    cars = [_vehicle(c["mass"][k], c["izz"][k]) for k in range(2)]
    zero = jnp.zeros(())
    states = [State(jnp.array([-5.0, 0.0, HEIGHT / 2]), jnp.stack([c["speed"], zero, zero]), zero, zero, zero,
                    jnp.zeros(3)),
              State(jnp.stack([zero, c["offset"], jnp.asarray(HEIGHT / 2)]), jnp.zeros(3), c["yaw"], zero, zero,
                    jnp.zeros(3))]
    contact = Contact(jnp.zeros(3), jnp.array([1.0, 0.0, 0.0]), c["restitution"], jnp.asarray(0.5), zero)
    first = automatic_exchange(cars[0], states[0], cars[1], states[1], contact, 0.0, auto_point=True,
                               auto_normal=True)
    moved = [advance(s, first.contact.time) for s in states]
    start = M.Planar(jnp.stack([s.position[:2] for s in moved]), jnp.stack([s.yaw for s in moved]),
                     jnp.stack([v.velocity_after[:2] for v in first.vehicles]),
                     jnp.stack([v.yaw_rate_after for v in first.vehicles]))
    return start, first._replace(rest=None)


def programs(seconds, slots, plan):
    """(prepare, watched, watched packed, alone), each jitted over a batch of cases (the first with the quick
    settings); the three variants in blocks of ``BLOCK_ROWS`` on the CPU's path (``plan``), all rows at once on the
    accelerator's, as ``batch.stages.run`` runs a blocked stage."""

    def watched(c, start, first, packed=False):
        cars = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *(_vehicle(c["mass"][k], c["izz"][k]) for k in range(2)))
        moving = jax.vmap(lambda m, izz: M.body(m, izz, HEIGHT / 2, CHASSIS, _wheels(c), c["road"], M.TIME_STEP))
        none = M.Planar(jnp.zeros((0, 2)), jnp.zeros(0), jnp.zeros((0, 2)), jnp.zeros(0))  # no fixed object
        bodies = Bodies(cars, jnp.full(2, HEIGHT / 2), moving(c["mass"], c["izz"]), none)
        one = jnp.ones(1)
        watch = Watch(c["restitution"] * one, 0.5 * one, 0.0 * one, jnp.asarray(APPROACH_TOLERANCE))
        out = interact(bodies, start, first, (0, 1), watch, max_exchanges=slots, time_limit=seconds, packed=packed)
        return (out.count, out.exhausted, jnp.stack([r.rest_position for r in out.rest]),
                jnp.stack([r.time_to_rest for r in out.rest]))

    def alone(c, start, first):
        rest = jax.vmap(lambda m, izz, s: ML.to_rest(m, izz, HEIGHT / 2, CHASSIS, _wheels(c), c["road"], s,
                                                    time_limit=seconds))(c["mass"], c["izz"], start)
        return rest.rest_position, rest.time_to_rest

    def blocked(f):
        return jax.jit(in_blocks(jax.vmap(f), BLOCK_ROWS, (0, 0, 0)) if plan.cpu else jax.vmap(f))

    return (jax.jit(jax.vmap(prepare), compiler_options=compiler_options(True)), blocked(watched),
            blocked(functools.partial(watched, packed=True)), blocked(alone))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=10.0, help="the time limit of the motion, s")
    parser.add_argument("--slots", type=int, default=8, help="the exchanges a case may have (the first included)")
    parser.add_argument("--plan", choices=("cpu", "accelerator"), help="the path (default: the default device's)")
    args = parser.parse_args(argv)
    plan = plan_for(args.plan)
    prep, watched, packed, alone = programs(args.seconds, args.slots, plan)
    c = {k: jnp.asarray(v) for k, v in cases(args.cases).items()}
    t = time.perf_counter()
    start, first = jax.block_until_ready(prep(c))
    prepare_s = time.perf_counter() - t
    compile_s, calls, results = {}, {}, {}
    for name, program in (("watched (interact)", watched), ("watched, packed", packed), ("alone (to_rest)", alone)):
        t = time.perf_counter()
        calls[name] = program.lower(c, start, first).compile()
        compile_s[name] = time.perf_counter() - t
    times = {name: [] for name in calls}
    for _ in range(args.repeats):
        for name, call in calls.items():
            t = time.perf_counter()
            results[name] = jax.block_until_ready(call(c, start, first))
            times[name].append(time.perf_counter() - t)
    names = list(calls)
    ratio = statistics.median(w / a for w, a in zip(times[names[0]], times[names[2]]))
    packed_ratio = statistics.median(p / w for w, p in zip(times[names[0]], times[names[1]]))
    apart = float(np.nanmax(np.abs(np.asarray(results[names[1]][2]) - np.asarray(results[names[0]][2]))))

    count, exhausted, _, watched_time = (np.asarray(x) for x in results[names[0]])
    alone_time = np.asarray(results[names[2]][1])
    touched = np.asarray(first.contact.status) == 0
    print(f"bench_interaction: {args.cases} two-vehicle cases ({int(touched.sum())} with a first exchange), up to "
          f"{args.slots} exchanges, motion to rest within {args.seconds:g} s at {M.TIME_STEP * 1000:g} ms, float64, "
          + (f"the CPU's path, blocks of {BLOCK_ROWS}" if plan.cpu else "the accelerator's path, all cases at once"))
    print(f"  {datetime.date.today()}, {platform.node()}, {jax.devices()[0].device_kind}, {os.cpu_count()} CPUs, "
          f"jax {jax.__version__}; {' '.join([os.path.basename(sys.argv[0])] + (argv or sys.argv[1:]))}")
    print(f"  first exchange and states (once, not measured): {prepare_s:.2f} s with its compile")
    for name in names:
        med = statistics.median(times[name])
        print(f"  {name:20s} {med:8.3f} s  {args.cases / med:10.4g} cases/s   (compile {compile_s[name]:.2f} s)")
    print(f"  watched / alone: {ratio:.2f}; packed / watched: {packed_ratio:.2f} (medians of {args.repeats} rounds' "
          f"ratios); rest positions packed and plain {apart:.1e} m apart at most")
    histogram = collections.Counter(count.tolist())
    print("  exchanges per case: " + ", ".join(f"{k}: {histogram[k]}" for k in sorted(histogram))
          + f"; exhausted {int(exhausted.sum())}; 2 or more {int((count >= 2).sum())}")
    later = {"watched": watched_time.max(-1), "alone": alone_time.max(-1)}  # the later vehicle's time to rest
    print("  time to rest of a case's later vehicle, median: " + ", ".join(
        f"{k} {np.median(t):.2f} s ({int((t >= args.seconds - 1e-9).sum())} at the time limit)"
        for k, t in later.items()))


if __name__ == "__main__":
    main()
