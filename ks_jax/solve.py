"""Solve cases: a case's inputs to the exchange's results (docs/model.md), for one case or for every
case of a file at once.

``solve_inputs`` is the case as a pure function of its inputs (jit, vmap and differentiate it at the
edge: ``ks_jax.sweep`` and ``fit`` do). It runs the case's pipeline (``stages``): for a given contact,
the exchange's own three stages; for automatic contact, the input rules, the contact (first touch,
overlap), and the exchange there. ``solve`` solves the cases of a file, grouped by contact mode, each
group in one compiled call.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .batch.stages import blocked, run
from .case import Case, CaseInputs, Motion, as_arrays, defined_output, to_pytrees, undefined_kind
from .case.scale import farthest_out_of_scale, move_scene, scene_origin, warn_far_from_origin
from .compilation import quick_jit
from .model import collision
from .model.automatic import automatic_stage, exchange_at_contact
from .model.checks import check_smoothing, input_status
from .model.motion import MAX_FRICTION as MAX_ROAD_FRICTION
from .model.motion import Chassis, Planar, Wheels
from .model.motion import to_rest as motion_to_rest
from .model.results import mask_invalid
from .model.types import INVALID_MOTION, INVALID_NONFINITE, INVALID_OVERFLOW, INVALID_SPEED_1, INVALID_SPEED_2, OK
from .model.types import ContactResult, ExchangeResult, VehicleResult, status_text


def solve_inputs(inputs: CaseInputs, auto_point: bool = False, auto_normal: bool = False,
                 smoothing=0.0, pole: bool = False, motion: Motion | None = None) -> ExchangeResult:
    """One case's results from its inputs (pure, unbatched; jit, vmap and grad at the edge).

    ``auto_point``/``auto_normal`` (static) select automatic contact for the centroid and/or the normal;
    otherwise the exchange is at the case state. ``pole`` (static): vehicle 2 is a pole, which automatic
    contact meets as a disc (``Case.pole``). ``motion`` (static, ``Case.motion``): where the inputs have a
    ``road``, how the vehicles' motion to rest is integrated (the result's ``rest``). A negative ``speed``
    (reachable by ``set_input``, a sweep or a fit, never by a case file) gives status INVALID_SPEED_1/2 and NaN
    results (``speed_status``), unless another input breaks a rule first.

    Of the pipeline's stages (``stages``) only automatic contact's first, the input rules, is fenced off
    (``batch.stages.run``): every later loop reads the rules, and XLA would derive them again inside each
    loop that reads a stand-in input, in a program over twice the size to compile. The others are fused
    freely: a fit differentiates this function, and a fence costs tracing time under ``jax.jacfwd``."""
    return run(stages(auto_point, auto_normal, smoothing, pole, motion), (inputs,), in_axes=None,
               fenced=1 if auto_point or auto_normal else False)


def stages(auto_point: bool, auto_normal: bool, smoothing=0.0, pole: bool = False, motion: Motion | None = None):
    """The case's pipeline, functions of a row's ``CaseInputs`` and the outputs of the stages before
    (``ks_jax.batch.stages.run``): the exchange's own stages (``model.collision.stages``) at a given
    contact; for automatic contact, the input rules, the contact (``model.automatic.automatic_stage``)
    and the exchange there (``exchange_at_contact``). ``smoothing``: a Python number or an array. With
    ``motion`` (a ``case.Motion``), the last stage moves the vehicles on from the exchange to rest
    (``to_rest``): the result's ``rest``."""
    exchange_stages = _exchange_stages(auto_point, auto_normal, smoothing, pole)
    if motion is None:
        return exchange_stages
    *first, last = exchange_stages
    auto = auto_point or auto_normal

    def exchange_and_rest(inputs, *earlier):
        result = last(inputs, *earlier)
        states = to_pytrees(inputs)[1:4:2]
        if auto:  # the vehicles at the exchange: where automatic contact put them, where it could
            status, found = earlier
            ok = status == OK
            states = tuple(jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), s_auto, s)
                           for s_auto, s in zip((found.state1, found.state2), states))
        return to_rest(inputs, result, states, motion)

    return (*first, blocked(exchange_and_rest))


def _exchange_stages(auto_point, auto_normal, smoothing, pole):
    if auto_point or auto_normal:
        def rules(inputs):
            return input_status(*to_pytrees(inputs))

        def contact(inputs, status):
            return automatic_stage(*to_pytrees(inputs), inputs.contact.normal_pitch, status,
                                   auto_point=auto_point, auto_normal=auto_normal, pole=pole)

        def exchange(inputs, status, auto):
            return with_speed_status(inputs, exchange_at_contact(*to_pytrees(inputs), status, auto, smoothing))

        return rules, contact, exchange
    prepare, impulse, results = collision.stages(smoothing)

    def prepared(inputs):
        p = prepare(*to_pytrees(inputs))
        return p._replace(status=speed_status(inputs, p.status))

    def found(inputs, p):
        return impulse(*to_pytrees(inputs), p)

    def derived(inputs, p, j):
        return results(*to_pytrees(inputs), p, j)

    return prepared, found, derived


def to_rest(inputs: CaseInputs, result: ExchangeResult, states, motion: Motion) -> ExchangeResult:
    """``result`` with ``rest``: each vehicle's motion from its state at the exchange (``states``, the pair of
    ``model.types.State``) with its velocity and yaw rate after it, to rest (``model.motion.to_rest``).

    A row whose exchange is invalid, or whose motion's inputs break their rules (``motion_rules``: a swept or
    fitted value can, a case file cannot), has NaN in every result and, for the latter, status
    INVALID_MOTION. Such rows move from harmless stand-ins (at rest, on a default road), so that their
    gradients stay finite."""
    road = inputs.road
    rules = motion_rules(road)
    status = result.contact.status
    valid = status < INVALID_NONFINITE
    ok = valid & rules
    status = jnp.where(valid & ~rules, jnp.int32(INVALID_MOTION), status).astype(status.dtype)
    result = mask_invalid(result, ~(valid & ~rules))
    result = result._replace(contact=result.contact._replace(status=status))
    friction = jnp.where(ok, road.friction, 0.7)
    rest = []
    for v, after, state, vr in zip(inputs.vehicles, road.vehicles, states, result.vehicles):
        if after is None:  # a fixed object does not move
            rest.append(None)
            continue
        after = jax.tree_util.tree_map(lambda x, d: jnp.where(ok, x, d), after, _stand_in(after))
        start = Planar(jnp.where(ok, state.position[:2], 0.0), jnp.where(ok, state.yaw, 0.0),
                       jnp.where(ok, vr.velocity_after[:2], 0.0), jnp.where(ok, vr.angular_velocity_after[2], 0.0))
        mass, izz = jnp.where(ok, v.mass, 1.0), jnp.where(ok, jnp.asarray(v.inertia)[2, 2], 1.0)
        chassis = Chassis(after.wheelbase, after.track, after.cg_to_front_axle)
        wheels = Wheels(after.brake, after.steer, after.rolling_resistance)
        r = motion_to_rest(mass, izz, jnp.where(ok, v.cg_height, 0.0), chassis, wheels, friction, start,
                           dt=motion.time_step, time_limit=motion.time_limit, path=motion.path, reverse=motion.reverse)
        rest.append(mask_invalid(r, ok))
    return result._replace(rest=tuple(rest))


def motion_rules(road) -> jnp.ndarray:
    """Whether the motion's inputs keep their rules (docs/model.md, "Motion to rest"): road.friction in (0, 10]; per
    vehicle each brake fraction in [0, 1], 0 < cg_to_front_axle < wheelbase, track > 0 and
    0 <= rolling_resistance < road.friction; all finite. Traced, per row."""
    ok = (road.friction > 0) & (road.friction <= MAX_ROAD_FRICTION)
    for after in road.vehicles:
        if after is None:
            continue
        b = jnp.asarray(after.brake)
        ok = ok & jnp.all((b >= 0) & (b <= 1)) & (after.cg_to_front_axle > 0) \
            & (after.cg_to_front_axle < after.wheelbase) & jnp.isfinite(after.wheelbase) & (after.track > 0) \
            & jnp.isfinite(after.track) & jnp.isfinite(after.steer) \
            & (after.rolling_resistance >= 0) & (after.rolling_resistance < road.friction)
    return ok


def _stand_in(after):
    """A harmless vehicle's wheels (a row that breaks a rule moves on these, at rest)."""
    like = lambda x, v: jnp.full_like(jnp.asarray(x, jnp.result_type(float)), v)  # noqa: E731
    return after._replace(wheelbase=like(after.wheelbase, 2.8), track=like(after.track, 1.6),
                          cg_to_front_axle=like(after.cg_to_front_axle, 1.2), brake=like(after.brake, 0.0),
                          steer=like(after.steer, 0.0), rolling_resistance=like(after.rolling_resistance, 0.015))


def speed_status(inputs: CaseInputs, status):
    """``status`` (() int, the exchange's) with INVALID_SPEED_1 (2) where vehicle 1's (2's) ``speed`` is
    negative and ``status`` is not already invalid (the exchange's reasons come first).

    A case file refuses a negative speed; a swept, sampled or fitted one can reach it, and ``to_pytrees``
    would turn it into travel backwards along the course. Such a row gets this status and NaN results
    instead (traceable, per row)."""
    s1, s2 = inputs.vehicles[0].speed, inputs.vehicles[1].speed
    code = jnp.where(s1 < 0, INVALID_SPEED_1, jnp.where(s2 < 0, INVALID_SPEED_2, OK))
    return jnp.where((code != OK) & (status < INVALID_NONFINITE), code, status).astype(jnp.asarray(status).dtype)


def with_speed_status(inputs: CaseInputs, result: ExchangeResult) -> ExchangeResult:
    """``result`` of ``inputs`` with ``speed_status`` applied: that status and NaN results where a negative
    speed makes the row invalid."""
    status = speed_status(inputs, result.contact.status)
    result = mask_invalid(result, status == result.contact.status)
    return result._replace(contact=result.contact._replace(status=status))


def _solve_rows(inputs, auto_point, auto_normal, smoothing, pole=False, motion=None):
    """``solve_inputs`` of every row of ``inputs``. One row is solved unbatched: XLA compiles a batch of
    one row to a program several times the size of one unbatched row's."""
    pipeline = stages(auto_point, auto_normal, smoothing, pole, motion)
    if jax.tree_util.tree_leaves(inputs)[0].shape[0] == 1:
        row = run(pipeline, (jax.tree_util.tree_map(lambda x: x[0], inputs),), in_axes=None)
        return jax.tree_util.tree_map(lambda x: x[None], row)
    return run(pipeline, (inputs,))


_solve = quick_jit(_solve_rows, static_argnums=(1, 2, 3, 4, 5))  # a file's few cases: compiling is most of the time


@dataclass
class Solution:
    """A solved case: ``result`` is an ExchangeResult of NumPy arrays (None for an invalid case)."""

    case: Case
    result: ExchangeResult | None
    status: str

    def notes(self) -> list:
        """Why a case gave what a user may not expect, in words (the panel prints them, ``--json`` lists them
        under "notes"). A vehicle still moving at the motion's time limit is named, with its speed then. A contact that is not closing at the centroid ("separating": no impulse) says the
        relative velocity there along the normal; where the case gives the normal, the reversed normal would be
        closing and the normal points from vehicle 1's CG's side towards vehicle 2's, it says that the normal
        may point the wrong way (docs/model.md: from vehicle 2 into vehicle 1, from a fixed object into the
        vehicle)."""
        if self.result is None or self.status.startswith("invalid"):
            return []
        notes = self._moving_notes()
        if self.status != "separating":
            return notes
        c = self.result.contact
        n, u = np.asarray(c.normal, float), np.asarray(c.closing_velocity, float)
        un = float(n @ u)
        notes.insert(0, f"no impulse: at the centroid the relative velocity along the normal is n . u = {un:.4g} m/s "
                     "(vehicle 1's velocity there minus vehicle 2's); an exchange needs it below 0 (closing)")
        x1, x2 = (np.asarray(v.position, float)[:2] for v in self.case.inputs.vehicles)
        # reversed it would be closing, and it points from vehicle 1's CG towards vehicle 2's (an object's
        # point): vehicles that are truly parting, under a normal that points the right way, get no such note
        if not self.case.auto_normal and un > 0 and float(n[:2] @ (x1 - x2)) < 0:
            names = self.case.vehicle_names
            into = (f"from the fixed {self.case.fixed.kind} into {names[0]}" if self.case.fixed is not None
                    else f"from vehicle 2 ({names[1]}) into vehicle 1 ({names[0]})")
            azimuth = round(math.degrees(math.atan2(-n[1], -n[0])) % 360.0, 1) % 360.0  # 359.97 is 0.0
            notes.append(f"the normal may point the wrong way: it must point {into}; reversed (azimuth "
                         f"{azimuth:.1f} deg) the vehicles would be closing at {un:.4g} m/s there")
        return notes

    def _moving_notes(self) -> list:
        rest = self.result.rest
        if rest is None:
            return []
        return [f"vehicles[{i}] ({self.case.vehicle_names[i]}) still moves at the time limit of the motion to rest "
                f"({self.case.motion.time_limit:g} s): its rest position, yaw, time and distance are where it is then; "
                "lengthen road.time_limit, or brake its wheels (after.wheels)"
                for i, r in enumerate(rest) if r is not None and not bool(r.at_rest)]

    def to_dict(self) -> dict:
        """{"name", "contact": {...}, "vehicles": [{...}, {...}]}: SI, the result names of docs/model.md,
        (against a fixed object: one vehicle, and "fixed": the object as the file gives it, SI, angles in rad;
        where ``notes`` has something to say, "notes": its list of sentences),
        the status in words, NaN as None: what ``ks-jax solve --json`` prints for the case. An invalid case
        has only its status. What the model leaves undefined is None too (``case.defined_output``): the
        impulse's directions where none was exchanged; the first-contact time, centroid, normal, closing
        and separation velocities and EES where the vehicles never touch; the course after of a vehicle at
        rest; and ``time`` at a given contact (it belongs to automatic contact)."""
        if self.result is None or self.status.startswith("invalid"):
            return {"name": self.case.name, "contact": {"status": self.status}, "vehicles": []}
        r = self.result
        contact = {k: _plain(defined_output(r, f"contact.{k}") if undefined_kind(f"contact.{k}")
                             else getattr(r.contact, k)) for k in ContactResult._fields if k != "status"}
        contact["status"] = self.status
        if not (self.case.auto_point or self.case.auto_normal):
            contact["time"] = None  # no search for a first contact: the exchange is at the case state
        vehicles = []
        fixed = self.case.fixed
        for i, (name, v) in enumerate(zip(self.case.vehicle_names, r.vehicles)):
            if i == 1 and fixed is not None:
                break  # a fixed object has no per-vehicle results
            d = {"name": name}
            d.update({k: _plain(defined_output(r, f"vehicles[{i}].{k}") if undefined_kind(f"vehicles[{i}].{k}")
                                else getattr(v, k)) for k in VehicleResult._fields})
            d["pdof_clock"] = None if d["pdof_clock"] is None else int(d["pdof_clock"])
            if r.rest is not None:
                d.update({k: _plain(x) for k, x in r.rest[i]._asdict().items() if k != "path"})
            vehicles.append(d)
        out = {"name": self.case.name, "contact": contact, "vehicles": vehicles}
        notes = self.notes()
        if notes:  # only where there is something to say: a case solved as expected has the keys of the model
            out["notes"] = notes
        if fixed is not None:
            out["fixed"] = {"name": self.case.vehicle_names[1],
                            **{k: _plain(v) for k, v in fixed._asdict().items() if v is not None and k != "kind"},
                            "kind": fixed.kind}
        return out


def motion_paths(solution: Solution):
    """Each vehicle's path from the exchange to rest, for a picture (the top view): a tuple of (k, 4) NumPy arrays
    (time s, x m, y m, yaw rad), from the exchange to the step at which it rests (or the time limit), None for a
    fixed object; None for a case without a road or an invalid one. The case is solved again, keeping every
    step (``case.Motion.path``)."""
    case = solution.case
    if case.motion is None or solution.result is None or solution.status.startswith("invalid"):
        return None
    again = solve(dataclasses.replace(case, motion=dataclasses.replace(case.motion, path=True)))
    paths = []
    for r in again.result.rest:
        if r is None:
            paths.append(None)
            continue
        p = np.asarray(r.path, float)
        end = int(np.argmax(p[:, 0] >= p[-1, 0])) + 1  # the first step at the final time: at rest from there
        paths.append(p[:end])
    return tuple(paths)


def _plain(x):
    """A result as plain JSON-ready data: a bool, a float (None for NaN), or a list of them; a vector that
    is undefined throughout is None, not a list of Nones."""
    x = np.asarray(x)
    if x.dtype == np.bool_:
        return bool(x) if x.ndim == 0 else [bool(v) for v in x]
    if x.ndim == 0:
        v = float(x)
        return None if not math.isfinite(v) else v
    if not np.isfinite(x).any():
        return None
    return [_plain(v) for v in x]


def _status(case: Case, code) -> str:
    """The status words of a solved case; an overflow also names the input farthest out of scale."""
    text = status_text(code)
    if int(code) == INVALID_OVERFLOW:
        text += f"; the input farthest out of scale: {farthest_out_of_scale(case.inputs)}"
    return text


def solve(cases, smoothing: float = 0.0):
    """Solve a Case (-> Solution) or a list of cases (-> list of Solution).

    Valid cases are solved together in one vmapped call per contact mode; an invalid case (bad input in
    a file of several cases) gets status "invalid: <reason>" and no numbers. In float32 (JAX's default) a
    case more than ``case.scale.FAR_IN_FLOAT32`` (1 km) from the origin is solved about its CGs' midpoint
    (``case.scale.scene_origin``), and its ``contact.point`` is float64."""
    single = isinstance(cases, Case)
    cases = [cases] if single else list(cases) if isinstance(cases, (list, tuple)) else None
    if cases is None or not all(isinstance(c, Case) for c in cases):
        raise TypeError("solve takes a Case or a list of them: ks_jax.load_case(path) reads a case file")
    check_smoothing(smoothing)
    out: list[Solution | None] = [None] * len(cases)
    groups: dict[tuple, list[int]] = {}
    for i, c in enumerate(cases):
        if c.valid:
            # a pole is met as a disc by automatic contact only: at a given contact it is any other case
            groups.setdefault((c.auto_point, c.auto_normal, c.pole and (c.auto_point or c.auto_normal), c.motion,
                               c.fixed is not None and c.motion is not None), []).append(i)
        else:
            out[i] = Solution(c, None, c.error if c.error.startswith("invalid") else f"invalid: {c.error}")
    for (auto_point, auto_normal, pole, motion, _), idx in groups.items():
        stacked = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *[cases[i].inputs for i in idx])
        origin = scene_origin(stacked)  # float32 far from the origin: solved about the CGs' midpoint
        if origin is not None:
            stacked = move_scene(stacked, origin, auto_point)
        warn_far_from_origin(stacked, what="a case", about="the origin" if origin is None else "its CGs' midpoint",
                             auto_point=auto_point)
        res = _solve(as_arrays(stacked), auto_point, auto_normal, float(smoothing), pole, motion)
        res = jax.tree_util.tree_map(np.asarray, res)
        if origin is not None:
            point = res.contact.point.astype(np.float64)
            point[:, :2] += origin
            res = res._replace(contact=res.contact._replace(point=point))
            if res.rest is not None:
                res = res._replace(rest=tuple(None if r is None else r._replace(
                    rest_position=r.rest_position.astype(np.float64) + origin) for r in res.rest))
        for k, i in enumerate(idx):
            row = jax.tree_util.tree_map(lambda x: x[k], res)
            out[i] = Solution(cases[i], row, _status(cases[i], row.contact.status))
    return out[0] if single else out
