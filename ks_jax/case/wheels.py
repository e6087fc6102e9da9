"""How a vehicle's wheels run, as a case file gives it: the keys ``wheels``, ``steer`` and ``rolling_resistance``
of a vehicle's ``after`` (docs/model.md, "Motion to rest") and of each phase of its ``approach`` (docs/model.md,
"The approach: the case file"), read and checked alike. Shared by ``load`` and ``approach``."""

from __future__ import annotations

import math

from .errors import CaseError
from .fields import given, number, shown, where

ROLLING_RESISTANCE = 0.015  # a free wheel's rolling resistance where the file gives none
MAX_STEER = 60.0  # deg: the front wheels' angle at most, either way


def wheels(value, path, case_name) -> list:
    """"free" (0, 0, 0, 0), "locked" (1, 1, 1, 1) or four brake fractions in [0, 1] (front left, front right, rear
    left, rear right)."""
    if value == "free":
        return [0.0] * 4
    if value == "locked":
        return [1.0] * 4
    if not isinstance(value, (list, tuple)) or len(value) != 4:
        raise CaseError(f"{where(case_name, path)} = {shown(value)}: must be \"free\", \"locked\" or four brake "
                        "fractions in [0, 1] (front left, front right, rear left, rear right)")
    out = [number(b, "dimensionless", f"{path}[{k}]", case_name) for k, b in enumerate(value)]
    for k, b in enumerate(out):
        if not 0 <= b <= 1:
            raise CaseError(f"{where(case_name, f'{path}[{k}]')} = {shown(value[k])}: a brake fraction must be in "
                            "[0, 1] (0 free rolling, 1 locked)")
    return out


def running(entry: dict, path, friction, case_name, surface="the road's friction") -> tuple:
    """(brake fractions (4), steer rad, rolling resistance) of a table ``entry`` at ``path`` (a vehicle's ``after``,
    an approach phase) on a road of ``friction`` (``surface``: how a message names it). Defaults: free wheels, no
    steer, a rolling resistance of ``ROLLING_RESISTANCE`` (at most ``friction``: on a frictionless road the wheels
    roll without resistance unless the file says otherwise)."""
    brake = wheels(entry.get("wheels", "free"), f"{path}.wheels", case_name)
    steer = number(entry["steer"], "angle", f"{path}.steer", case_name) if "steer" in entry else 0.0
    if abs(steer) > math.radians(MAX_STEER):
        raise CaseError(f"{where(case_name, path + '.steer')} = {given(entry['steer'], steer, 'angle')}: must be "
                        f"within +-{MAX_STEER:g} deg")
    f = (number(entry["rolling_resistance"], "dimensionless", f"{path}.rolling_resistance", case_name)
         if "rolling_resistance" in entry else min(ROLLING_RESISTANCE, friction))
    if not (0 <= f < friction or f == friction == 0):
        value = shown(entry["rolling_resistance"]) if "rolling_resistance" in entry else f"{f:.4g} (its default)"
        raise CaseError(f"{where(case_name, path + '.rolling_resistance')} = {value}: must be >= 0 and below "
                        f"{surface} ({friction:.4g}), or 0 on a road of friction 0")
    return brake, steer, f
