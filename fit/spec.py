"""A fit's unknowns and evidence, read and checked (docs/fit.md), and the ``Problem`` made of them.

An ``Unknown`` is one scalar input path with bounds (SI), an optional start and an optional
Gaussian prior. An ``Evidence`` is one scalar result path (docs/model.md, "Paths"; or a
pre-impact input such as ``vehicles[1].speed``) with a measured value and a sigma, in the
units the results use: SI, degrees for ``pdof``, ``impulse_azimuth``, ``impulse_elevation``
and ``course_after``; radians for angle *inputs* used as evidence (``vehicles[0].yaw``).

Everything here is checked at the edge: a bad path, unit, bound or sigma raises
``ks_jax.case.CaseError`` naming it; ``check_batch`` checks a batch's cases at once and reports
each bad one without losing the others. What a fit compiles from them is in ``fit.problem``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ks_jax import units as U
from ks_jax.case import (
    CIRCULAR_OUTPUTS,
    Case,
    add_times,
    CaseError,
    PathError,
    automatic_part,
    follows_tow,
    on_fixed_object,
    check_output_path,
    input_ties,
    get_input,
    input_kind,
    output_kind,
    parse_output_value,
    parse_path,
    path_key,
    times_asked,
    with_times,
    without_approach,
    without_road,
    without_time,
)

from .crush import as_ees, is_crush_energy
from .problem import Problem
from .report import fmt

# outputs that are piecewise constant (no gradient): they cannot be evidence for a fit
NOT_FITTABLE = {"sliding": "a yes/no flag", "at_rest": "a yes/no flag", "pdof_clock": "rounded to whole hours",
                "status": "a status code"}
# inputs that are angles on the circle (radians inside)
CIRCULAR_INPUTS = {"yaw", "course", "roll", "normal"}
# physical limits of inputs, checked against the bounds of an unknown: field -> (lo, hi, strict lo)
INPUT_LIMITS = {
    "restitution": (-1.0, 1.0, False), "friction": (0.0, math.inf, False),
    "penetration_time": (0.0, math.inf, False), "speed": (0.0, math.inf, False),
    "mass": (0.0, math.inf, True), "inertia": (0.0, math.inf, True), "length": (0.0, math.inf, True),
    "width": (0.0, math.inf, True), "height": (0.0, math.inf, True),
    "brake": (0.0, 1.0, False), "rolling_resistance": (0.0, math.inf, False), "wheelbase": (0.0, math.inf, True),
    "track": (0.0, math.inf, True), "cg_to_front_axle": (0.0, math.inf, True),
}


@dataclass(frozen=True)
class Unknown:
    """An input to fit. ``path``: an input path ("vehicles[1].speed", "contact.point[0]");
    ``lower``/``upper``: bounds in SI (rad for angles; +-inf for none: for a speed, restitution,
    friction or penetration time, its own limit: 0, or -1 and 1); ``start``: optional SI
    start of the first multi-start; ``prior``: optional (mean, sigma) in SI, a Gaussian prior."""

    path: str
    lower: float = -math.inf
    upper: float = math.inf
    start: float | None = None
    prior: tuple | None = None


@dataclass(frozen=True)
class Evidence:
    """A measured result. ``path``: a result path (docs/model.md, "Paths") with a component index
    for vectors ("vehicles[0].delta_v_body[0]") or a pre-impact input ("vehicles[0].speed");
    ``value`` and ``sigma`` in the result's units (SI; degrees for pdof, impulse_azimuth,
    impulse_elevation, course_after; rad for angle inputs)."""

    path: str
    value: float
    sigma: float


# ---------------------------------------------------------------------------------------
# reading unknowns and evidence (units at the edge)


def _num(value, kind, where, case_name):
    try:
        x = U.parse_quantity(value, kind)
    except U.UnitError as err:
        raise CaseError(f"case '{case_name}': {where} = {U.as_typed(value)}: {err}") from None
    except KeyError:
        raise CaseError(f"case '{case_name}': {where}: no unit kind '{kind}'") from None
    if math.isnan(x):
        raise CaseError(f"case '{case_name}': {where} = {U.as_typed(value)}: must be a number")
    return x


def _field(path):
    return parse_path(path)[2]


def _q(x_si, path) -> str:
    """A value of ``path`` as the user reads it: '100 mph (44.7 m/s)' (errors quote the file's units,
    not only the SI number they were converted to)."""
    if math.isinf(x_si):
        return "none"  # a bound not given
    try:
        kind = input_kind(path)
    except PathError:
        try:
            kind = output_kind(path)
        except (PathError, KeyError):
            return f"{x_si:.6g} (SI)"
    return fmt(float(x_si), kind, digits=6, si=True)


def unknown_path(case: Case, path: str) -> None:
    """Refuse a path that names no input of ``case`` that a fit can vary (CaseError)."""
    name = case.name
    try:
        get_input(case.inputs, path)
    except PathError as err:
        raise CaseError(f"case '{name}': unknowns: {err}") from None
    field = _field(path)
    if why := on_fixed_object(case, path) or without_road(case, path) or follows_tow(case, path):
        raise CaseError(f"case '{name}': unknowns: {why}")
    if automatic_part(case, path):
        raise CaseError(f"case '{name}': unknowns: {path}: contact.{field} is automatic in this case; "
                        f"give contact.{field} in the case to fit it")


class PathChecks:
    """The path checks of a batch of cases (``unknown_path``, ``evidence_kind``), each made once per path and
    ``ks_jax.case.path_key`` (cases with one key accept and refuse the same paths); a refused path is checked
    again for every case, so that each case's error names that case."""

    def __init__(self):
        self._seen = {}

    def unknown(self, case: Case, path) -> None:
        key = ("unknown", path, path_key(case)) if isinstance(path, str) else None  # not a path: refused below
        if key not in self._seen:
            unknown_path(case, path)
            self._seen[key] = None

    def evidence(self, case: Case, path):
        key = ("evidence", path, path_key(case)) if isinstance(path, str) else None
        if key not in self._seen:
            self._seen[key] = evidence_kind(case, path)
        return self._seen[key]


def _own_limits(field, lower, upper):
    """The bounds with a missing one (+-inf) taken as the input's own limit, for inputs whose limit a bound may
    reach (a speed's 0, restitution's -1 and 1); scalars or arrays."""
    if field not in INPUT_LIMITS or INPUT_LIMITS[field][2]:
        return lower, upper
    plo, phi, _ = INPUT_LIMITS[field]
    return np.where(lower == -math.inf, plo, lower), np.where(upper == math.inf, phi, upper)


def _unknown_faults(field, lo, hi, start, has_start, mean, sigma, has_prior):
    """The rules of ``check_unknown``, in its order, each as a mask of the unknowns that break it (scalars or
    arrays of one shape; bounds after ``_own_limits``; start, mean and sigma only read where given)."""
    lo, hi, start, mean, sigma = (np.asarray(a, np.float64) for a in (lo, hi, start, mean, sigma))
    has_start, has_prior = np.asarray(has_start, bool), np.asarray(has_prior, bool)
    limits = np.zeros(np.shape(lo), bool)
    if field in INPUT_LIMITS:
        plo, phi, strict = INPUT_LIMITS[field]
        limits = (lo < plo) | (strict & (lo <= plo)) | (hi > phi)
    with np.errstate(invalid="ignore"):
        return (("lower", np.isfinite(lo) & (np.abs(lo) > MAX_MAGNITUDE)),
                ("upper", np.isfinite(hi) & (np.abs(hi) > MAX_MAGNITUDE)),
                ("order", ~(lo < hi)),
                ("limits", limits),
                ("start", has_start & ~((lo <= start) & (start <= hi))),
                ("prior", has_prior & ~((np.abs(mean) <= MAX_MAGNITUDE) & (MIN_SIGMA <= sigma)
                                        & (sigma <= MAX_MAGNITUDE))))


def _si_numbers(where, **numbers):
    """Refuse (CaseError) any of ``numbers`` (name -> value of an ``Unknown`` or ``Evidence`` made in Python) that is
    not one real number: those are SI; a quantity with its unit is the file format's (``parse_unknowns``,
    ``parse_evidence``)."""
    for what, x in numbers.items():
        if isinstance(x, (bool, np.bool_, str, bytes)) or np.ndim(x) != 0 or not np.isrealobj(x):
            hint = (f" (made in Python it is SI: a number; {x!r} with its unit belongs in a case file's map, "
                    "read by fit.parse_unknowns or fit.parse_evidence)") if isinstance(x, str) else ""
            raise CaseError(f"{where}: {what} = {U.as_typed(x)}: must be one number{hint}")


def check_unknown(case: Case, u: Unknown, checks: PathChecks | None = None) -> Unknown:
    """Refuse an unknown whose path, bounds, start or prior break a rule (CaseError). ``checks``: the batch's
    path checks (default: the path checked here)."""
    name, path = case.name, u.path
    (checks or PathChecks()).unknown(case, path)
    if u.prior is not None and (not isinstance(u.prior, (tuple, list)) or len(u.prior) != 2):
        raise CaseError(f"case '{name}': unknowns: {path}: prior = {U.as_typed(u.prior)}: must be (mean, sigma)")
    _si_numbers(f"case '{name}': unknowns: {path}", lower=u.lower, upper=u.upper,
                **({} if u.start is None else {"start": u.start}),
                **({} if u.prior is None else {"prior mean": u.prior[0], "prior sigma": u.prior[1]}))
    field = _field(path)
    lo, hi = (float(b) for b in _own_limits(field, float(u.lower), float(u.upper)))
    start = math.nan if u.start is None else u.start
    mean, sigma = u.prior if u.prior is not None else (math.nan, math.nan)
    broken = next((rule for rule, bad in _unknown_faults(field, lo, hi, start, u.start is not None, mean, sigma,
                                                         u.prior is not None) if bad), None)
    where = f"case '{name}': unknowns: {path}"
    if broken in ("lower", "upper"):
        b = lo if broken == "lower" else hi
        raise CaseError(f"{where}: {broken} bound {_q(b, path)}: beyond {MAX_MAGNITUDE:g} (SI), where the fit cannot "
                        "compute; leave the bound out for none")
    if broken == "order":
        raise CaseError(f"{where}: bounds [{_q(lo, path)}, {_q(hi, path)}]: the lower bound must be below the upper "
                        "bound")
    if broken == "limits":
        plo, phi, strict = INPUT_LIMITS[field]
        rule = f"{'>' if strict else '>='} {plo}" + (f" and <= {phi}" if math.isfinite(phi) else "")
        raise CaseError(f"{where}: bounds [{_q(lo, path)}, {_q(hi, path)}]: {field} must be {rule} (SI), so must its "
                        "bounds")
    if broken == "start":
        raise CaseError(f"{where}: start {_q(u.start, path)} is outside the bounds [{_q(lo, path)}, {_q(hi, path)}]")
    if broken == "prior":
        raise CaseError(f"{where}: prior (mean {_q(mean, path)}, sigma {_q(sigma, path)}): needs a mean within "
                        f"+/-{MAX_MAGNITUDE:g} and a sigma within [{MIN_SIGMA:g}, {MAX_MAGNITUDE:g}] (SI)")
    return Unknown(path.replace(" ", ""), lo, hi, None if u.start is None else float(u.start),
                   None if u.prior is None else (float(mean), float(sigma)))


def evidence_kind(case: Case, path: str):
    """(is_output, period) of an evidence path; CaseError naming the path if it names nothing
    that can be fitted."""
    try:
        why = on_fixed_object(case, path) or without_road(case, path) or without_approach(case, path) \
            or follows_tow(case, path) or without_time(case, path)
    except PathError as err:  # a path of no form that names anything
        raise CaseError(f"case '{case.name}': evidence: {err}") from None
    if why:
        raise CaseError(f"case '{case.name}': evidence: {why}")
    try:
        group, vi, field, idx = check_output_path(path)
    except PathError as out_err:
        try:
            get_input(case.inputs, path)
        except PathError:
            raise CaseError(f"case '{case.name}': evidence: {out_err}") from None
        field = _field(path)
        return False, (2 * math.pi if field in CIRCULAR_INPUTS else 0.0)
    if field in NOT_FITTABLE:
        raise CaseError(f"case '{case.name}': evidence: {path}: {field} is {NOT_FITTABLE[field]} and cannot be "
                        "fitted (it has no gradient)")
    if (group, field) == ("contact", "time") and not (case.auto_point or case.auto_normal):
        raise CaseError(f"case '{case.name}': evidence: {path}: the first-contact time exists with automatic "
                        "contact only (a case without contact.point or contact.normal); with an explicit contact "
                        "the exchange is at the case state")
    return True, (360.0 if field in CIRCULAR_OUTPUTS else 0.0)


# The magnitudes a fit computes with (SI, or degrees where the results are in degrees): beyond them a residual
# (value - prediction) / sigma or a bound transform overflows or loses every digit (docs/fit.md, "Limits")
MAX_MAGNITUDE = 1e12
MIN_SIGMA = 1e-9


def _evidence_faults(value, sigma):
    """The rules of ``check_evidence`` on its numbers, in its order, each as a mask of the evidence that breaks it
    (scalars or arrays of one shape)."""
    value, sigma = np.asarray(value, np.float64), np.asarray(sigma, np.float64)
    with np.errstate(invalid="ignore"):
        return (("value", ~np.isfinite(value)),
                ("magnitude", ~(np.abs(value) <= MAX_MAGNITUDE)),
                ("sigma", ~(np.isfinite(sigma) & (sigma > 0))),
                ("sigma range", ~((MIN_SIGMA <= sigma) & (sigma <= MAX_MAGNITUDE))))


def check_evidence(case: Case, e: Evidence, checks: PathChecks | None = None) -> Evidence:
    """Refuse evidence whose path, value or sigma break a rule (CaseError). ``checks``: the batch's path checks
    (default: the path checked here)."""
    (checks or PathChecks()).evidence(case, e.path)  # raises on a bad path
    _si_numbers(f"case '{case.name}': evidence: {e.path}", value=e.value, sigma=e.sigma)
    broken = next((rule for rule, bad in _evidence_faults(e.value, e.sigma) if bad), None)
    where = f"case '{case.name}': evidence: {e.path}"
    if broken == "value":
        raise CaseError(f"{where}: value {e.value:g} must be finite")  # not _q's "none" (a bound not given)
    if broken == "magnitude":
        raise CaseError(f"{where}: value {_q(e.value, e.path)}: beyond {MAX_MAGNITUDE:g} (SI), no measurement of a "
                        "crash is; the fit cannot compute with it")
    if broken == "sigma":
        raise CaseError(f"{where}: sigma = {_q(e.sigma, e.path)}: must be positive (an exact measurement is an input, "
                        "not evidence)")
    if broken == "sigma range":
        shown = f"{e.sigma:.3g} (SI)" if e.sigma < MIN_SIGMA else _q(e.sigma, e.path)
        raise CaseError(f"{where}: sigma = {shown}: must be within [{MIN_SIGMA:g}, {MAX_MAGNITUDE:g}] (SI): a smaller "
                        "one makes its residual overflow, a larger one says nothing (leave the evidence out)")
    return Evidence(e.path.replace(" ", ""), float(e.value), float(e.sigma))


def _evidence_value(case, path, value, where):
    try:
        check_output_path(path)
    except PathError:
        return _num(value, input_kind(path), where, case.name)
    return parse_output_value(value, path, case.name, where)


def parse_unknowns(case: Case, spec, checks: PathChecks | None = None) -> list[Unknown]:
    """Unknowns from the file format of docs/fit.md: a map path -> {"bounds": [lo, hi],
    "start": x, "prior": {"mean": x, "sigma": s}} (quantities as numbers or unit strings; bare
    numbers are SI except angles in degrees and rates in deg/s). ``Unknown`` objects pass as
    they are (SI). A list of paths or of ``Unknown`` is accepted too. ``checks``: a batch's ``PathChecks``."""
    checks = checks or PathChecks()
    if spec is None:
        raise CaseError(f"case '{case.name}': unknowns: missing (name at least one input to fit)")
    if isinstance(spec, (list, tuple)):
        items = [(u.path, u) if isinstance(u, Unknown) else (u, {}) for u in spec]
    elif isinstance(spec, dict):
        items = list(spec.items())
    else:
        raise CaseError(f"case '{case.name}': unknowns: must be a map from input paths to bounds, got "
                        f"{U.as_typed(spec)}")
    if not items:
        raise CaseError(f"case '{case.name}': unknowns: empty (name at least one input to fit)")
    out = []
    for path, d in items:
        if isinstance(d, Unknown):
            out.append(check_unknown(case, d, checks))
            continue
        try:
            get_input(case.inputs, path)  # names a scalar input? (before asking its kind)
            kind = input_kind(path)
        except PathError as err:
            raise CaseError(f"case '{case.name}': unknowns: {err}") from None
        if d is None:
            d = {}
        if not isinstance(d, dict):
            raise CaseError(f"case '{case.name}': unknowns: {path} = {U.as_typed(d)}: must be a map with 'bounds' "
                            "(and optional 'start', 'prior')")
        extra = set(d) - {"bounds", "start", "prior"}
        if extra:
            raise CaseError(f"case '{case.name}': unknowns: {path}.{sorted(extra)[0]}: unknown field "
                            "(known: bounds, start, prior)")
        lo, hi = -math.inf, math.inf
        if "bounds" in d:
            b = d["bounds"]
            if not isinstance(b, (list, tuple)) or len(b) != 2:
                raise CaseError(f"case '{case.name}': unknowns: {path}.bounds = {U.as_typed(b)}: must be "
                                "[lower, upper]")
            lo = -math.inf if b[0] is None else _num(b[0], kind, f"unknowns: {path}.bounds[0]", case.name)
            hi = math.inf if b[1] is None else _num(b[1], kind, f"unknowns: {path}.bounds[1]", case.name)
        start = None if d.get("start") is None else _num(d["start"], kind, f"unknowns: {path}.start", case.name)
        prior = None
        if d.get("prior") is not None:
            p = d["prior"]
            if isinstance(p, dict) and set(p) == {"mean", "sigma"}:
                pm, ps = p["mean"], p["sigma"]
            elif isinstance(p, (list, tuple)) and len(p) == 2:
                pm, ps = p
            else:
                raise CaseError(f"case '{case.name}': unknowns: {path}.prior = {U.as_typed(p)}: must be "
                                "{\"mean\": x, \"sigma\": s}")
            prior = (_num(pm, kind, f"unknowns: {path}.prior.mean", case.name),
                     _num(ps, kind, f"unknowns: {path}.prior.sigma", case.name))
        out.append(check_unknown(case, Unknown(path, lo, hi, start, prior), checks))
    paths = [u.path for u in out]
    for p in paths:
        if paths.count(p) > 1:
            raise CaseError(f"case '{case.name}': unknowns: {p} is named twice")
    return out


def parse_evidence(case: Case, spec, checks: PathChecks | None = None) -> list[Evidence]:
    """Evidence from the file format: a list of {"quantity": path, "value": q, "sigma": q}
    (unit strings parsed with the path's kind); ``Evidence`` objects pass as they are. ``checks``: a batch's
    ``PathChecks``."""
    checks = checks or PathChecks()
    if spec is None:
        raise CaseError(f"case '{case.name}': evidence: missing (give at least one measured result)")
    if not isinstance(spec, (list, tuple)) or not spec:
        raise CaseError(f"case '{case.name}': evidence: must be a non-empty list of "
                        "{\"quantity\", \"value\", \"sigma\"}")
    out = []
    for k, e in enumerate(spec):
        if isinstance(e, Evidence):
            if is_crush_energy(e.path):
                e = Evidence(*as_ees(case, e.path, e.value, e.sigma, f"case '{case.name}': evidence[{k}] ({e.path})"))
            out.append(check_evidence(case, e, checks))
            continue
        if not isinstance(e, dict):
            raise CaseError(f"case '{case.name}': evidence[{k}] = {U.as_typed(e)}: must be "
                            "{\"quantity\", \"value\", \"sigma\"}")
        extra = set(e) - {"quantity", "path", "value", "sigma", "note", "source", "time"}
        if extra:
            raise CaseError(f"case '{case.name}': evidence[{k}].{sorted(extra)[0]}: unknown field "
                            "(known: quantity, value, sigma, time, note, source)")
        path = e.get("quantity", e.get("path"))
        if is_crush_energy(path):
            out.append(check_evidence(case, _crush_evidence(case, k, path, e), checks))
            continue
        if path is None or "value" not in e or "sigma" not in e:
            raise CaseError(f"case '{case.name}': evidence[{k}]: needs quantity, value and sigma")
        for path, value, sigma in _at_times(case, k, path, e):
            checks.evidence(case, path)  # a clear error for a bad path first
            value = _evidence_value(case, path, value, f"evidence: {path}.value")
            sigma = _evidence_value(case, path, sigma, f"evidence: {path}.sigma")
            out.append(check_evidence(case, Evidence(path, value, sigma), checks))
    return out


def _crush_evidence(case: Case, k: int, path: str, e: dict) -> Evidence:
    """A crush-energy evidence entry (``crush.as_ees``): its value and sigma as energies, or neither (from the
    vehicle's crush profile)."""
    where = f"case '{case.name}': evidence[{k}] ({path})"
    if "time" in e:
        raise CaseError(f"{where}: a crush energy has no time (it is the crash's whole crush)")
    given = [key for key in ("value", "sigma") if key in e]
    if len(given) == 1:
        raise CaseError(f"{where}: give both value and sigma (energies), or neither (from the vehicle's crush "
                        "profile and stiffness)")
    energy = sigma = None
    if given:
        energy = _num(e["value"], "energy", f"evidence[{k}].value", case.name)
        sigma = _num(e["sigma"], "energy", f"evidence[{k}].sigma", case.name)
    return Evidence(*as_ees(case, path, energy, sigma, where))


MAX_TABLE = 200  # rows of one evidence table at most (an event data recorder's pre-crash table has 5 to 50)


def _at_times(case: Case, k: int, path, e: dict):
    """The (path, value, sigma) of an evidence entry: itself, or with a ``time`` (s from the impact) its quantity at
    that time ("vehicles[0].speed@-2.5"), or with a list of times (a table, an event data recorder's pre-crash speeds)
    one for each, ``value`` a list as long and ``sigma`` one for all or a list as long."""
    if "time" not in e:
        return [(path, e["value"], e["sigma"])]
    where = f"case '{case.name}': evidence[{k}]"
    times, values, sigmas = e["time"], e["value"], e["sigma"]
    table = isinstance(times, (list, tuple))
    if not table:
        times, values, sigmas = [times], [values], [sigmas]
    elif not (0 < len(times) <= MAX_TABLE) or not isinstance(values, (list, tuple)) or len(values) != len(times):
        raise CaseError(f"{where}: a table: time and value must be lists of the same length (1 to {MAX_TABLE}), "
                        f"got {len(times)} time(s) and {len(values) if isinstance(values, (list, tuple)) else 'one'} "
                        "value(s)")
    if table and not isinstance(sigmas, (list, tuple)):
        sigmas = [sigmas] * len(times)
    if len(sigmas) != len(times):
        raise CaseError(f"{where}.sigma: one sigma for the whole table, or a list as long as its times "
                        f"({len(times)})")
    if "@" in str(path):
        raise CaseError(f"{where}: {path}: give the time once, either after '@' in the quantity or as \"time\"")
    out = []
    for j, (t, value, sigma) in enumerate(zip(times, values, sigmas)):
        at = _num(t, "time", f"evidence[{k}].time" + (f"[{j}]" if table else ""), case.name)
        out.append((f"{str(path).replace(' ', '')}@{at!r}", value, sigma))
    return out


def check_batch(cases, unknowns_specs, evidence_specs, checks: PathChecks) -> list:
    """Each case's (unknowns, evidence, Problem), checked as ``parse_unknowns``, ``parse_evidence`` and
    ``make_problem`` check them, for all the cases at once where their specs are lists of ``Unknown`` and
    ``Evidence`` that name the same paths (without spaces) as the first such case's: the paths checked once per
    kind of case (``PathChecks``), the numbers in NumPy over all the cases (``_unknown_faults``,
    ``_evidence_faults``). None for every other case, and for one that breaks a rule: check it alone, for its
    error. An unknown whose missing bound is the input's own limit is given that bound, as ``check_unknown``
    gives it; the others are the objects given."""
    out = [None] * len(cases)
    plain = lambda spec, kind: isinstance(spec, (list, tuple)) and spec and all(type(x) is kind for x in spec)  # noqa: E731
    ok = [i for i, (c, u, e) in enumerate(zip(cases, unknowns_specs, evidence_specs))
          if isinstance(c, Case) and c.valid and plain(u, Unknown) and plain(e, Evidence)]
    if not ok:
        return out
    paths = tuple(u.path for u in unknowns_specs[ok[0]])
    evidence_paths = tuple(e.path for e in evidence_specs[ok[0]])
    if (len(set(paths)) < len(paths) or any(not isinstance(p, str) or " " in p for p in paths + evidence_paths)):
        return out
    ok = [i for i in ok if tuple(u.path for u in unknowns_specs[i]) == paths
          and tuple(e.path for e in evidence_specs[i]) == evidence_paths]
    kinds = {}  # path_key -> the evidence's (is_output, period), or None where a path is refused
    keys = {i: path_key(cases[i]) for i in ok}
    for i in ok:
        key = keys[i]
        if key not in kinds:
            try:
                for p in paths:
                    checks.unknown(cases[i], p)
                kinds[key] = tuple(checks.evidence(cases[i], p) for p in evidence_paths)
            except CaseError:
                kinds[key] = None
    ok = [i for i in ok if kinds[keys[i]] is not None]
    nan = math.nan
    try:
        u = np.array([[(x.lower, x.upper, nan if x.start is None else x.start, x.start is not None,
                        *(x.prior if x.prior is not None else (nan, nan)), x.prior is not None)
                       for x in unknowns_specs[i]] for i in ok], np.float64).reshape(len(ok), len(paths), 7)
        e = np.array([[(x.value, x.sigma) for x in evidence_specs[i]] for i in ok],
                     np.float64).reshape(len(ok), len(evidence_paths), 2)
    except (TypeError, ValueError):  # not numbers: checked alone
        return out
    bad = np.zeros(len(ok), bool)
    limited = []
    for j, path in enumerate(paths):
        field = _field(path)
        lo, hi = _own_limits(field, u[:, j, 0], u[:, j, 1])
        limited.append((lo, hi))
        for _, broken in _unknown_faults(field, lo, hi, u[:, j, 2], u[:, j, 3] > 0, u[:, j, 4], u[:, j, 5],
                                         u[:, j, 6] > 0):
            bad |= broken
    for _, broken in _evidence_faults(e[..., 0], e[..., 1]):
        bad |= broken.any(axis=1)
    ties_matter = any(_field(p) in ("yaw", "cg_height") for p in paths)
    asked = times_asked(evidence_paths)
    problems = {}
    lows, highs = np.stack([lo for lo, _ in limited], 1), np.stack([hi for _, hi in limited], 1)
    given = (lows == u[..., 0]) & (highs == u[..., 1])  # (K, n): False where a missing bound was given its limit
    limit_given = set(np.flatnonzero(~given.all(axis=1)).tolist())
    for k in np.flatnonzero(~bad).tolist():
        i = ok[k]
        case = cases[i]
        unknowns = list(unknowns_specs[i])
        if k in limit_given:
            for j in np.flatnonzero(~given[k]).tolist():
                x = unknowns[j]
                unknowns[j] = Unknown(x.path, float(lows[k, j]), float(highs[k, j]), x.start, x.prior)
        ties = input_ties(case, list(paths)) if ties_matter else ()
        key = (keys[i], ties, bool(case.auto_point), bool(case.auto_normal), bool(case.pole),
               add_times(case.motion, asked), case.between)
        if key not in problems:
            evidence = tuple((p, *kind) for p, kind in zip(evidence_paths, kinds[key[0]]))
            problems[key] = Problem(paths, ties, evidence, *key[2:])
        out[i] = (unknowns, list(evidence_specs[i]), problems[key])
    return out


def make_problem(case: Case, unknowns: list[Unknown], evidence: list[Evidence],
                 checks: PathChecks | None = None) -> Problem:
    if not case.valid:
        raise CaseError(case.error)
    ties = input_ties(case, [u.path for u in unknowns])
    checks = checks or PathChecks()
    ev = tuple((e.path, *checks.evidence(case, e.path)) for e in evidence)
    return Problem(tuple(u.path for u in unknowns), ties, ev, bool(case.auto_point), bool(case.auto_normal),
                   bool(case.pole), with_times(case.motion, [e.path for e in evidence]), case.between)


def output_units(path: str, is_output: bool) -> str:
    """The unit kind of an evidence path ("degrees" for outputs reported in degrees)."""
    return output_kind(path) if is_output else input_kind(path)
