"""A vehicle's measured crush in case files (docs/model.md, "Crush energy: the case file"): its ``stiffness`` (the
damaged side's A and B, with optional uncertainties) and its ``crush_profile`` (the damage width, 2, 4 or 6 depths
equally spaced across it, an optional angle of the principal force off the damaged surface's normal, and optional
uncertainties), read and checked into a ``CrushProfile`` (SI). What the crush energy is, is ``model.crush``.

    "stiffness": {"A": "300 lbf/in", "B": "90 lbf/in^2", "A_sigma": "30 lbf/in", "B_sigma": "10 lbf/in^2"},
    "crush_profile": {"width": "62 in", "depths": ["10 in", "12 in", "13 in", "12 in", "8 in", "2 in"],
                      "pdof": "10 deg", "depth_sigma": "0.5 in"}
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..model.crush import crush_energy
from .errors import CaseError
from .fields import check_keys, given, number, shown, where
from .schema import CRUSH_PROFILE_FIELDS, STIFFNESS_FIELDS, TEXT_FIELDS

SIDES = ("front", "rear", "left", "right")  # the damaged side a profile may name (else the top view finds it)
POINTS = (2, 4, 6)  # how many depths a profile may have: CRASH3's protocols
MAX_ALPHA = 45.0  # deg: the principal force's angle off the damaged surface's normal at most (a factor of 2)
EXAMPLE = ('"stiffness": {"A": "300 lbf/in", "B": "90 lbf/in^2"}, "crush_profile": {"width": "62 in", '
           '"depths": ["10 in", "12 in", "13 in", "12 in", "8 in", "2 in"]}')


class CrushProfile(NamedTuple):
    """One vehicle's measured crush and its damaged side's stiffness, SI: ``width`` (m), ``depths`` (n,) m across
    it, ``a`` (N/m), ``b`` (N/m^2), ``alpha`` (rad, the principal force off the surface's normal) and the
    uncertainties (one sigma each, 0 where not given): ``width_sigma``, ``depth_sigma`` (of each depth, taken as
    independent), ``a_sigma``, ``b_sigma`` (taken as independent); ``side``: the damaged side (``SIDES``), or None
    where the file does not say (the top view takes the side nearest the exchange's centroid)."""

    width: float
    depths: tuple
    a: float
    b: float
    alpha: float = 0.0
    width_sigma: float = 0.0
    depth_sigma: float = 0.0
    a_sigma: float = 0.0
    b_sigma: float = 0.0
    side: str | None = None


def crush_energies(crush: tuple, objects: tuple) -> tuple:
    """``CaseInputs.crush_energy`` of a case's ``crush`` (``read_crush``) and fixed ``objects``: () for a case without
    crush profiles, else per body its crush energy (J, ``model.crush.crush_energy``) or None."""
    if not crush:
        return ()
    return tuple(None if p is None else float(crush_energy(p.width, p.depths, p.a, p.b, p.alpha)) for p in crush) + (
        (None,) * len(objects))


def read_crush(vehicles: list, sizes, case_name) -> tuple:
    """A ``CrushProfile`` or None for each of a case's ``vehicles`` entries (the file's tables); () where no vehicle
    has one. ``sizes``: each vehicle's (length, width) in m (a depth or width beyond the vehicle's length is
    refused)."""
    if not any(isinstance(v, dict) and ("stiffness" in v or "crush_profile" in v) for v in vehicles):
        return ()
    return tuple(_vehicle(v, i, size, case_name) if isinstance(v, dict) else None
                 for i, (v, size) in enumerate(zip(vehicles, sizes)))


def _vehicle(d, i, size, case_name):
    path = f"vehicles[{i}]"
    has = [k for k in ("stiffness", "crush_profile") if k in d]
    if not has:
        return None
    if len(has) == 1:
        other = "crush_profile" if has[0] == "stiffness" else "stiffness"
        raise CaseError(f"{where(case_name, f'{path}.{other}')}: missing field; the crush energy needs the measured "
                        f"crush profile and the damaged side's stiffness together, e.g. {EXAMPLE}")
    stiffness, profile = d["stiffness"], d["crush_profile"]
    for key, table, fields in (("stiffness", stiffness, STIFFNESS_FIELDS),
                               ("crush_profile", profile, CRUSH_PROFILE_FIELDS)):
        if not isinstance(table, dict):
            raise CaseError(f"{where(case_name, f'{path}.{key}')} = {shown(table)}: must be a table/object, e.g. "
                            f"{EXAMPLE}")
        check_keys(table, set(fields) | TEXT_FIELDS, f"{path}.{key}", case_name)
    longest = max(size)

    def value(table, key, kind, required=True, least=0.0, strict=False, most=None, most_rule=""):
        where_ = f"{path}.{'stiffness' if table is stiffness else 'crush_profile'}.{key}"
        if key not in table:
            if required:
                raise CaseError(f"{where(case_name, where_)}: missing field, e.g. {EXAMPLE}")
            return 0.0
        x = number(table[key], kind, where_, case_name, orientation=False)
        if x < least or (strict and x == least):
            rule = "must be positive" if strict else "must be >= 0"
            raise CaseError(f"{where(case_name, where_)} = {given(table[key], x, kind)}: {rule}")
        if most is not None and x > most:
            raise CaseError(f"{where(case_name, where_)} = {given(table[key], x, kind)}: {most_rule}")
        return x

    a = value(stiffness, "A", "force_per_length", strict=True)
    b = value(stiffness, "B", "force_per_area", strict=True)
    a_sigma = value(stiffness, "A_sigma", "force_per_length", required=False)
    b_sigma = value(stiffness, "B_sigma", "force_per_area", required=False)
    beyond = f"must not exceed the vehicle's length ({longest:.4g} m)"
    width = value(profile, "width", "length", strict=True, most=longest, most_rule=beyond)
    width_sigma = value(profile, "width_sigma", "length", required=False)
    depth_sigma = value(profile, "depth_sigma", "length", required=False)
    alpha = 0.0
    if "pdof" in profile:
        alpha = number(profile["pdof"], "angle", f"{path}.crush_profile.pdof", case_name, orientation=False)
        if abs(alpha) > math.radians(MAX_ALPHA) + 1e-12:
            shown_alpha = given(profile["pdof"], alpha, "angle")
            raise CaseError(f"{where(case_name, f'{path}.crush_profile.pdof')} = {shown_alpha}: must be within "
                            f"+-{MAX_ALPHA:g} deg (the principal force's angle off the damaged "
                            "surface's normal; its correction 1 + tan^2 doubles the energy at 45 deg and grows "
                            "without bound toward 90)")
    side = profile.get("side")
    if side is not None and side not in SIDES:
        raise CaseError(f"{where(case_name, f'{path}.crush_profile.side')} = {shown(side)}: must be one of "
                        f"{', '.join(SIDES)} (the damaged side; C1 is at the left end of the front or rear, at the "
                        "front end of a side)")
    raw = profile.get("depths")
    if raw is None:
        raise CaseError(f"{where(case_name, f'{path}.crush_profile.depths')}: missing field, e.g. {EXAMPLE}")
    if not isinstance(raw, (list, tuple)) or len(raw) not in POINTS:
        count = f" ({len(raw)} depths)" if isinstance(raw, (list, tuple)) else ""
        raise CaseError(f"{where(case_name, f'{path}.crush_profile.depths')} = {shown(raw)}{count}: must be a list of "
                        "2, 4 or 6 depths, equally spaced across the damage width (C1 .. Cn)")
    depths = []
    for k, c in enumerate(raw):
        at = f"{path}.crush_profile.depths[{k}]"
        x = number(c, "length", at, case_name)
        if not 0.0 <= x <= longest:
            raise CaseError(f"{where(case_name, at)} = {given(c, x, 'length')}: must be >= 0 and at most the "
                            f"vehicle's length ({longest:.4g} m)")
        depths.append(x)
    return CrushProfile(width, tuple(depths), a, b, alpha, width_sigma, depth_sigma, a_sigma, b_sigma, side)
