"""``solve``: the cases of a file solved at once, grouped by what their pipeline is made of, each group in one
compiled call; and ``trajectories`` (``motion_paths``), each vehicle's path to rest and before the impact for a
picture.

A group of cases with a road is solved keeping every step of its motions (``case.Motion.path``) where those paths are
small (``PATH_BYTES``): the top view draws them, so the numbers and the picture of a file come from one compiled
program: solving again for the picture would compile a second program as large as the first (a watched motion's
program is most of a ``solve``'s time), while the kept steps add little to a run."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import numpy as np

from ..backend import Plan, plan_for
from ..batch.stages import run, run_row
from ..case import Case, as_arrays
from ..compilation import quick_jit
from ..model.checks import check_smoothing
from ..model.motion_loop import steps_for
from .origin import about_midpoint, moved_back
from .pipeline import stages
from .rules import status_words
from .solution import Solution


def _solve_rows(inputs, auto_point, auto_normal, smoothing, pole=False, motion=None, between=(0, 1),
                plan=Plan("cpu")):
    """``solve_inputs`` of every row of ``inputs``, computed as ``plan`` says. One row is solved unbatched:
    XLA compiles a batch of one row to a program several times the size of one unbatched row's."""
    pipeline = stages(auto_point, auto_normal, smoothing, pole, motion, between, packed=plan.packed)
    if jax.tree_util.tree_leaves(inputs)[0].shape[0] == 1:
        row = run_row(pipeline, (jax.tree_util.tree_map(lambda x: x[0], inputs),), fenced=len(pipeline), plan=plan)
        return jax.tree_util.tree_map(lambda x: x[None], row)
    return run(pipeline, (inputs,), plan=plan)


# a file's few cases: compiling is most of the time
_solve = quick_jit(_solve_rows, static_argnums=(1, 2, 3, 4, 5, 6, 7))

# the most a group's kept paths to rest may take (bytes): above it (a file of thousands of cases with a road) the
# group is solved without them, and a picture of one of its cases solves that case again
PATH_BYTES = 64 * 2**20


def _motion_kept(motion, rows: int, bodies: int):
    """``motion`` keeping every step where the paths to rest of ``rows`` cases of ``bodies`` bodies fit in
    ``PATH_BYTES`` (each step: time, x, y and yaw in float64), else ``motion`` as it is; None for no road."""
    if motion is None or motion.path:
        return motion
    size = rows * bodies * (steps_for(motion.time_limit, motion.time_step) + 1) * 4 * 8
    return dataclasses.replace(motion, path=True) if size <= PATH_BYTES else motion


def solve(cases, smoothing: float = 0.0, plan: Plan | str | None = None):
    """Solve a Case (-> Solution) or a list of cases (-> list of Solution).

    Valid cases are solved together in one vmapped call per contact mode; an invalid case (bad input in
    a file of several cases) gets status "invalid: <reason>" and no numbers. In float32 (JAX's default) a
    case more than ``case.scale.FAR_IN_FLOAT32`` (1 km) from the origin is solved about its CGs' midpoint
    (``case.scale.scene_origin``), and its ``contact.point`` is float64. ``plan``: how the rows are computed, a
    ``backend.Plan`` or its path ("cpu", "accelerator"); default, the path of JAX's default devices. Cases with a
    road keep their paths (module docstring): ``trajectories`` reads them from the solution."""
    single = isinstance(cases, Case)
    cases = [cases] if single else list(cases) if isinstance(cases, (list, tuple)) else None
    if cases is None or not all(isinstance(c, Case) for c in cases):
        raise TypeError("solve takes a Case or a list of them: ks_jax.load_case(path) reads a case file")
    check_smoothing(smoothing)
    plan = plan_for(plan)
    out: list[Solution | None] = [None] * len(cases)
    groups: dict[tuple, list[int]] = {}
    for i, c in enumerate(cases):
        if c.valid:
            # a pole is met as a disc by automatic contact only: at a given contact it is any other case; cases of
            # one group stack into one batch: the same bodies and parts of inputs (their tree)
            groups.setdefault((c.auto_point, c.auto_normal, c.pole and (c.auto_point or c.auto_normal), c.motion,
                               c.between, jax.tree_util.tree_structure(c.inputs)), []).append(i)
        else:
            out[i] = Solution(c, None, c.error if c.error.startswith("invalid") else f"invalid: {c.error}")
    for (auto_point, auto_normal, pole, motion, between, _), idx in groups.items():
        stacked = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *[cases[i].inputs for i in idx])
        stacked, origin = about_midpoint(stacked, auto_point)  # float32 far from the origin: about the CGs' midpoint
        kept = _motion_kept(motion, len(idx), len(cases[idx[0]].vehicle_names))
        res = _solve(as_arrays(stacked), auto_point, auto_normal, float(smoothing), pole, kept, between, plan)
        res = moved_back(jax.tree_util.tree_map(np.asarray, res), origin)
        for k, i in enumerate(idx):
            row = jax.tree_util.tree_map(lambda x: x[k], res)
            out[i] = Solution(cases[i], row, status_words(cases[i], row.contact.status))
    return out[0] if single else out


class Trajectories(NamedTuple):
    """Every vehicle's path before and after the impact, for a picture (the top view), from one solve of the case
    with every step kept (``trajectories``). Each path is a (k, 4) NumPy array of time s, x m, y m, yaw rad."""

    rest: tuple  # per body: from the exchange to the step at which it rests (or the time limit); None for a fixed
    # object (as ``motion_paths``)
    approach: tuple | None  # per body: from its approach's start to the impact (docs/model.md, "The approach"), time
    # <= 0 increasing to 0 there; None for a body without an approach; None for a case where no vehicle has one


def trajectories(solution: Solution) -> Trajectories | None:
    """Each vehicle's paths to rest and, where it has an approach, before the impact (``Trajectories``): those
    ``solve`` kept (module docstring), else from one more solve of the case keeping every step
    (``case.Motion.path``). None for a case without a road (which has neither) or an invalid one."""
    case = solution.case
    if case.motion is None or solution.result is None or solution.status.startswith("invalid"):
        return None
    kept = solution.result
    if any(r is not None and r.path is None for r in kept.rest):  # solved without its paths
        kept = solve(dataclasses.replace(case, motion=dataclasses.replace(case.motion, path=True))).result
    paths = []
    for r in kept.rest:
        if r is None:
            paths.append(None)
            continue
        p = np.asarray(r.path, float)
        end = int(np.argmax(p[:, 0] >= p[-1, 0])) + 1  # the first step at the final time: at rest from there
        paths.append(p[:end])
    approach = kept.approach
    if approach is not None:
        approach = tuple(None if a is None else np.asarray(a.path, float) for a in approach)
    return Trajectories(tuple(paths), approach)


def motion_paths(solution: Solution):
    """Each vehicle's path from the exchange to rest, for a picture (the top view): a tuple of (k, 4) NumPy arrays
    (time s, x m, y m, yaw rad), from the exchange to the step at which it rests (or the time limit), None for a
    fixed object; None for a case without a road or an invalid one. As ``trajectories``, which gives the approaches'
    paths too."""
    found = trajectories(solution)
    return None if found is None else found.rest
