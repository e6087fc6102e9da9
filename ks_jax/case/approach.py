"""A vehicle's approach in case files (docs/model.md, "The approach: the case file"): its ``approach`` entry, a list of
phases, earliest first, the last ending at the impact, read and checked into ``CaseInputs.approach`` (the phases'
values, SI) and ``Motion.approach`` (each phase's kind). How the approach is worked back from the impact is
``model.approach``.

A phase runs the wheels as a vehicle's ``after`` does (``wheels``, ``steer``, ``rolling_resistance``: read by
``case.wheels.running``), for a ``duration`` or over a ``distance`` of the CG's path (a skid mark), on the road's
friction or a ``friction`` of its own: ``"approach": [{"wheels": "free", "duration": "1.5 s"}, {"wheels": "locked",
"distance": "48 ft"}]``.
"""

from __future__ import annotations

import numpy as np

from ..model.motion import MAX_FRICTION
from .errors import CaseError
from .fields import check_keys, given, number, shown, where
from .inputs import ApproachInputs, RoadInputs
from .schema import APPROACH_FIELDS, TEXT_FIELDS
from .wheels import running

KINDS = ("duration", "distance")  # what sets a phase's length: a time, or the CG's path (a skid mark)
MAX_PHASES = 8  # phases of one approach at most
MAX_DURATION = 60.0  # s: a phase's duration at most
MAX_DISTANCE = 1000.0  # m: a phase's distance at most
LIMITS = {"duration": (MAX_DURATION, "time", "s"), "distance": (MAX_DISTANCE, "length", "m")}
EXAMPLE = '[{"wheels": "locked", "distance": "48 ft"}]'


def read_approach(vehicles: list, road: RoadInputs | None, links, case_name) -> tuple:
    """(``CaseInputs.approach``, ``Motion.approach``) of a case's ``vehicles`` entries (the file's tables): for each
    vehicle an ``ApproachInputs`` (float arrays stacked over its phases, earliest first) and its phases' kinds, or
    None and () for a vehicle without an approach; ((), ()) for a case where no vehicle has one. ``road``: the case's
    ``RoadInputs`` (None for a case without a road, which cannot have an approach); ``links``: ``Motion.links`` (a
    towed vehicle cannot have one)."""
    given_by = [i for i, v in enumerate(vehicles) if isinstance(v, dict) and "approach" in v]
    if not given_by:
        return (), ()
    if road is None:
        raise CaseError(f"{where(case_name, 'road')}: missing field; a case with an approach "
                        f"(vehicles[{given_by[0]}].approach) needs a road: the approach is worked back from the impact "
                        "with the tyre model of the motion to rest, on the road's friction (add \"road\": "
                        "{\"friction\": 0.7}; docs/model.md, \"The approach\")")
    tows = {towed: tow for towed, tow, _ in links}
    inputs, kinds = [], []
    for i, v in enumerate(vehicles):
        if i not in given_by:
            inputs.append(None)
            kinds.append(())
            continue
        path = f"vehicles[{i}].approach"
        value = v["approach"]
        if i in tows:
            raise CaseError(f"{where(case_name, path)} = {shown(value)}: vehicles[{i}] is towed by vehicles[{tows[i]}] "
                            f"(vehicles[{i}].hitch): give the tow's approach (vehicles[{tows[i]}].approach); "
                            "articulated approaches are not modelled")
        if not isinstance(value, list) or not 1 <= len(value) <= MAX_PHASES:
            count = f" ({len(value)} phases)" if isinstance(value, list) else ""
            raise CaseError(f"{where(case_name, path)} = {shown(value)}{count}: must be a list of 1 to {MAX_PHASES} "
                            f"phases, earliest first, the last ending at the impact, e.g. {EXAMPLE}")
        phases = [_phase(p, f"{path}[{k}]", float(road.friction), case_name) for k, p in enumerate(value)]
        kinds.append(tuple(p[0] for p in phases))
        brake, steer, f, friction, length = (np.array([p[n] for p in phases], dtype=float) for n in range(1, 6))
        inputs.append(ApproachInputs(brake, steer, f, friction, length))
    return tuple(inputs), tuple(kinds)


def _phase(entry, path, road_friction, case_name) -> tuple:
    """(kind, brake fractions (4), steer rad, rolling resistance, friction, length: s or m) of one phase."""
    if not isinstance(entry, dict):
        raise CaseError(f"{where(case_name, path)} = {shown(entry)}: must be a table/object, e.g. "
                        "{\"wheels\": \"locked\", \"distance\": \"48 ft\"}")
    check_keys(entry, set(APPROACH_FIELDS) | TEXT_FIELDS, path, case_name)
    named = [k for k in KINDS if k in entry]
    if not named:
        raise CaseError(f"{where(case_name, path + '.duration')}: missing field (give duration, a time, or distance, "
                        "the CG's path over the phase: a skid mark)")
    if len(named) > 1:
        raise CaseError(f"{where(case_name, path)}: duration = {shown(entry['duration'])} and distance = "
                        f"{shown(entry['distance'])}: give duration or distance, not both")
    kind = named[0]
    most, quantity, unit = LIMITS[kind]
    raw = entry[kind]
    length = number(raw, quantity, f"{path}.{kind}", case_name)
    if not 0 < length <= most:
        raise CaseError(f"{where(case_name, f'{path}.{kind}')} = {given(raw, length, quantity)}: must be positive and "
                        f"at most {most:g} {unit}")
    friction = road_friction
    if "friction" in entry:
        friction = number(entry["friction"], "dimensionless", f"{path}.friction", case_name)
        if not 0 <= friction <= MAX_FRICTION:
            raise CaseError(f"{where(case_name, path + '.friction')} = {shown(entry['friction'])}: must be >= 0 (0: a "
                            f"frictionless surface) and at most {MAX_FRICTION:g} (no tyre grips more)")
    surface = "the phase's friction" if "friction" in entry else "the road's friction"
    brake, steer, f = running(entry, path, friction, case_name, surface)
    return kind, brake, steer, f, friction, length
