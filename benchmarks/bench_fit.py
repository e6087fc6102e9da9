"""Benchmark: many reconstructions at once (fit.reconstruct_batch), and the solver comparison.

    .venv/bin/python benchmarks/bench_fit.py                     # 1000 cases x 8 starts, Levenberg-Marquardt
    .venv/bin/python benchmarks/bench_fit.py --compare --n 200   # lm vs optax L-BFGS vs optax Adam
    .venv/bin/python benchmarks/bench_fit.py --noise-free        # evidence exactly the truth's: chi^2 0 is global
    .venv/bin/python benchmarks/bench_fit.py --max-starts 8      # one round of starts, as before the rounds
    .venv/bin/python benchmarks/bench_fit.py --plan accelerator --work  # the accelerator's calls, their work counted
    .venv/bin/python benchmarks/bench_fit.py --many 10000 --plan accelerator  # one call of 10^4 fits, its work

Cases: random oblique side impacts that slide at the centroid (vehicle 2's front into vehicle
1's right side, 60-120 deg apart, friction 0.1-0.35, restitution 0.05-0.3, initial yaw rates
up to 10 deg/s). Six unknowns: both speeds, restitution, friction, centroid x and y. Ten
evidence, perturbed by their sigmas: delta_v_body[0..1] of both vehicles (0.2 m/s), yaw rates
after (0.02 rad/s), speeds after (0.2 m/s), crush of both (0.03 m). Truth from the engine
(smoothing 1e-3, the fit's).

Figures: time of the second call (after compile) and of the first (with compile); "global":
the fit's chi^2 is no worse than the truth's (the multi-start found the global basin);
"2-sigma coverage": the share of unknowns within 2 Laplace standard errors of the truth
(95.4% if the standard errors are right and the global minimum was found); "all within 2 sigma":
cases with all six within (about 0.954^6 = 75% if calibrated, higher where errors correlate);
"converged": the solver's convergence test; "median starts": the starts a fit took (rounds of ``--starts`` until
the best fit repeats, ``fit.reconstruct``'s ``max_starts``); "host work": the call after compile again, its solver's
calls answered from a recording of that call (``replayed``), so that only the host's work around the device's is
timed (median of 3, per reconstruction); with ``--work``, the solver's work (``solver_work``). With
``--noise-free`` the global minimum is chi^2 0 (within 1e-6), and the cases it missed are listed.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import os
import platform
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import fit
from fit.synthetic import EVIDENCE, UNKNOWNS, oblique_case
from ks_jax.case import case_from_dict, get_input, get_output
from fit.solvers import SOLVERS
from ks_jax.solve import solve

SMOOTHING = 1e-3


def sliding_cases(n: int, seed: int, noisy: bool = True):
    """n cases that slide with a margin (still sliding at 1.5 x the friction) and have crush on
    both vehicles; returns (cases, truths (n, 6), evidence lists, unknown lists, chi2 at truth). ``noisy``
    False: the evidence is the engine's values at the truth, whose chi^2 is 0."""
    rng = np.random.default_rng(seed)
    cases = []
    while len(cases) < n:
        batch = [oblique_case(rng) for _ in range(2 * (n - len(cases)) + 8)]
        harder = [dict(d, contact=dict(d["contact"], friction=1.5 * d["contact"]["friction"])) for d in batch]
        sols = solve([case_from_dict(d) for d in batch + harder], smoothing=SMOOTHING)
        k = len(batch)
        for d, s, h in zip(batch, sols[:k], sols[k:]):
            r = s.result
            if (s.status == "ok" and bool(r.contact.sliding) and bool(h.result.contact.sliding)
                    and float(r.vehicles[0].crush) > 0.05 and float(r.vehicles[1].crush) > 0.05):
                cases.append((case_from_dict(d), r))
    cases = cases[:n]
    truths, evidence, unknowns, chi2_truth = [], [], [], []
    for case, result in cases:
        truth = [float(get_input(case.inputs, p)) for p in UNKNOWNS]
        noise = rng.standard_normal(len(EVIDENCE)) * float(noisy)
        evidence.append([fit.Evidence(p, float(get_output(result, p)) + s * e, s)
                         for (p, s), e in zip(EVIDENCE, noise)])
        chi2_truth.append(float(noise @ noise))
        px, py = truth[4] + rng.uniform(-0.5, 0.5), truth[5] + rng.uniform(-0.3, 0.3)  # the crush survey's guess
        unknowns.append([fit.Unknown(UNKNOWNS[0], 0.0, 40.0), fit.Unknown(UNKNOWNS[1], 0.0, 40.0),
                         fit.Unknown(UNKNOWNS[2], 0.0, 0.6), fit.Unknown(UNKNOWNS[3], 0.0, 1.0),
                         fit.Unknown(UNKNOWNS[4], px - 1.5, px + 1.5), fit.Unknown(UNKNOWNS[5], py - 1.0, py + 1.0)])
        truths.append(truth)
    return [c for c, _ in cases], np.array(truths), evidence, unknowns, np.array(chi2_truth)


def score(results, truths, chi2_truth):
    est = np.array([[r.estimate[p] for p in UNKNOWNS] for r in results])
    std = np.array([[r.std[p] for p in UNKNOWNS] for r in results])
    chi2 = np.array([r.chi2 for r in results])
    within = np.abs(est - truths) <= 2 * std
    return {"global": float(np.mean(chi2 <= chi2_truth + 1e-6)), "missed": np.flatnonzero(chi2 > chi2_truth + 1e-6),
            "chi2_missed": chi2[chi2 > chi2_truth + 1e-6], "starts": float(np.median([r.starts for r in results])),
            "coverage": float(np.mean(within)), "all2": float(np.mean(np.all(within, 1))),
            "converged": float(np.mean([r.converged for r in results])),
            "iterations": float(np.median([r.iterations for r in results]))}


SOLVER_CALLS = ("run_rows", "stick_thresholds")  # what fit.reconstruction asks of the device


@contextlib.contextmanager
def recording(calls):
    """Within the block, the solver's calls of ``fit.reconstruct_batch`` also append their results to ``calls``."""
    kept = {name: getattr(fit.reconstruction, name) for name in SOLVER_CALLS}

    def recorded(fn):
        def call(*a, **k):
            calls.append(fn(*a, **k))
            return calls[-1]
        return call

    try:
        for name, fn in kept.items():
            setattr(fit.reconstruction, name, recorded(fn))
        yield calls
    finally:
        for name, fn in kept.items():
            setattr(fit.reconstruction, name, fn)


@contextlib.contextmanager
def replayed(calls):
    """Within the block, the solver's calls of ``fit.reconstruct_batch`` return ``calls``'s results in turn: a
    rerun of the recorded call with the same arguments then does all of its host's work and none of the device's."""
    kept = {name: getattr(fit.reconstruction, name) for name in SOLVER_CALLS}
    answers = iter(calls)
    try:
        for name in kept:
            setattr(fit.reconstruction, name, lambda *a, **k: next(answers))
        yield
    finally:
        for name, fn in kept.items():
            setattr(fit.reconstruction, name, fn)


@contextlib.contextmanager
def solver_work():
    """Within the block, what the compiled solver computes for ``fit.reconstruct_batch``'s rounds of starts (a fit
    without Monte Carlo refits): the dict it yields gets each call's rows (padding included) and its loop's
    iterations, and the sum of the real rows' own iterations. The solver is vmapped: each of a call's rows is
    computed at every iteration of its loop, which runs until its slowest row converges, so ``rows x loop
    iterations`` is the work a device does, and the rows' own iterations the work the fits need. The count does not
    depend on the device: it is the same on a CPU with ``plan="accelerator"``."""
    work = {"calls": [], "own": 0}
    kept_solver, kept_rows = fit.rows.solver_for, fit.reconstruction.run_rows

    def counting(block, devices):
        solver = kept_solver(block, devices)

        def call(*a, **k):
            out = solver(*a, **k)
            work["calls"].append((block, int(np.max(np.asarray(out.iterations)))))
            return out
        return call

    def rounds(*a, **k):
        out = kept_rows(*a, **k)
        work["own"] += int(np.sum(out.iterations))
        return out

    fit.rows.solver_for, fit.reconstruction.run_rows = counting, rounds
    try:
        yield work
    finally:
        fit.rows.solver_for, fit.reconstruction.run_rows = kept_solver, kept_rows


def work_note(work) -> str:
    """``solver_work``'s dict in words: calls, their loop iterations, rows x loop iterations computed, and its ratio
    to the rows' own."""
    calls = work["calls"]
    computed = sum(r * it for r, it in calls)
    return (f"{len(calls)} solver calls of {'/'.join(str(r) for r in sorted({r for r, _ in calls}))} rows, "
            f"{sum(it for _, it in calls)} loop iterations (at most {max(it for _, it in calls)} a call), "
            f"{computed:.3g} row-iterations computed, {computed / max(work['own'], 1):.2f} x the rows' own")


def host_seconds(calls, fit_call, repeats=3):
    """Median seconds of ``fit_call()`` (the recorded call) with its solver's calls ``replayed``."""
    times = []
    for _ in range(repeats):
        with replayed(calls):
            t0 = time.perf_counter()
            fit_call()
            times.append(time.perf_counter() - t0)
    return float(np.median(times))


def run(solver, n, starts, seed, noise=True, max_starts=None, plan=None, work=False):
    cases, truths, evidence, unknowns, chi2_truth = sliding_cases(n, seed, noise)
    kw = dict(starts=starts, solver=solver, smoothing=SMOOTHING, max_starts=max_starts, plan=plan)
    t0 = time.perf_counter()
    fit.reconstruct_batch(cases, unknowns, evidence, seed=seed, **kw)
    first = time.perf_counter() - t0

    def second_call():
        return fit.reconstruct_batch(cases, unknowns, evidence, seed=seed + 1, **kw)

    with recording([]) as calls:
        t0 = time.perf_counter()
        results = second_call()
        second = time.perf_counter() - t0
    s = score(results, truths, chi2_truth) | {"host": host_seconds(calls, second_call)}
    if work:
        with solver_work() as counted:
            second_call()
        s["work"] = work_note(counted)
    return first, second, s


def repeated(many: int, *lists):
    """Each of ``lists`` (a batch's cases, unknowns, evidence) repeated to ``many`` entries: a batch of ``many``
    fits from fewer drawn cases, each fit its own rows."""
    k = -(-many // len(lists[0]))
    return [(c * k)[:many] for c in lists]


def many_fits(args) -> str:
    """One call of ``args.many`` fits, ``args.n`` cases repeated (as ``bench_device.py --many``), in a fresh
    process: its time, compile included, and its solver's work."""
    cases, _, evidence, unknowns, _ = sliding_cases(args.n, args.seed, not args.noise_free)
    many = repeated(args.many, cases, unknowns, evidence)
    with solver_work() as work:
        t0 = time.perf_counter()
        fit.reconstruct_batch(*many, starts=args.starts, seed=args.seed, solver=args.solver, smoothing=SMOOTHING,
                              max_starts=args.max_starts, plan=args.plan)
        wall = time.perf_counter() - t0
    return (f"{args.many} x {args.starts} starts ({args.n} cases repeated), plan {args.plan or 'default'}: one call "
            f"{wall:.1f} s, compile included; {work_note(work)}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1000, help="reconstructions (default 1000)")
    ap.add_argument("--starts", type=int, default=8, help="starts per reconstruction (default 8)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--solver", default="lm", choices=sorted(SOLVERS))
    ap.add_argument("--compare", action="store_true", help="run lm, lbfgs and adam")
    ap.add_argument("--noise-free", action="store_true", help="evidence without noise: the global minimum is chi^2 0")
    ap.add_argument("--max-starts", type=int, default=None,
                    help="fit.reconstruct's max_starts (default: its own; --max-starts 8: one round of 8 starts)")
    ap.add_argument("--plan", choices=("cpu", "accelerator"), default=None,
                    help="the fits' plan (default: that of this machine's devices)")
    ap.add_argument("--many", type=int, default=0,
                    help="instead: one call of this many fits (the --n cases repeated, each its own rows), timed with "
                         "its compile, and its solver's work (solver_work)")
    ap.add_argument("--work", action="store_true",
                    help="also count the solver's work (solver_work): its rows x loop iterations against the rows' "
                         "own, the same on every device")
    args = ap.parse_args(argv)
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {jax.devices()[0].device_kind}"
    cpu = ""
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    command = "python " + " ".join([Path(sys.argv[0]).as_posix(), *(argv or sys.argv[1:])])
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    print(f"machine: {cpu or machine} ({os.cpu_count()} cores, jax {jax.__version__}, {jax.default_backend()}, "
          "float64)")
    print(f"command: {command}\ndate: {date}")
    if args.many:
        print(many_fits(args))
        return
    rows = []
    for solver in (["lm", "lbfgs", "adam"] if args.compare else [args.solver]):
        first, second, s = run(solver, args.n, args.starts, args.seed, not args.noise_free, args.max_starts,
                               args.plan, args.work)
        row = (f"| {solver} | {args.n} x {args.starts} | {second:.2f} s | {first:.2f} s | {100 * s['global']:.1f}% | "
               f"{100 * s['coverage']:.1f}% | {100 * s['all2']:.1f}% | {100 * s['converged']:.1f}% | "
               f"{s['iterations']:.0f} | {s['starts']:.0f} | {1e3 * s['host'] / args.n:.3f} ms |")
        rows.append(row)
        print(row, flush=True)
        if "work" in s:
            print(f"  solver's work: {s['work']}")
        if len(s["missed"]):
            print(f"  not the global minimum: cases {[int(k) for k in s['missed'][:20]]}, chi^2 "
                  f"{[float(f'{c:.3g}') for c in s['chi2_missed'][:20]]}")
    header = ("| solver | fits x starts | time after compile | first call (with compile) | global | "
              "2-sigma coverage | all within 2 sigma | converged | median iterations | median starts | "
              "host work per fit |\n|---|---|---|---|---|---|---|---|---|---|---|")
    print(header)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
