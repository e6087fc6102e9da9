"""What people read: the auto-ees style panel of a solved case, SI beside US units, and the reported
values of a case file beside ks-jax's. (The JSON of ``ks-jax solve --json`` is ``Solution.to_dict``.)"""

from __future__ import annotations

import math
import textwrap
from typing import NamedTuple

import numpy as np

from . import units as U
from .case import CIRCULAR_OUTPUTS, at_rest_after, defined_output, impulse_exchanged, parse_output_value, parse_path
from .case.errors import visible
from .case.fixed import describe
from .model.contact import HORIZON


def _no_impulse(sol):
    """No impulse was exchanged (``case.impulse_exchanged``): its directions and a PDOF are undefined."""
    return not bool(impulse_exchanged(sol.result))


def _fmt(x, digits=3):
    x = float(x)
    if not math.isfinite(x):
        return "undefined"
    if abs(x) < 0.5 * 10.0**-digits:
        x = 0.0
    return f"{x:,.{digits}f}"


def angle_text(x, digits=1):
    """A direction in degrees, in [0, 360) as shown: 359.97 to one digit is 0.0, not 360.0."""
    x = float(x)
    return _fmt(round(x % 360.0, digits) % 360.0, digits) if math.isfinite(x) else "undefined"


def _quantity(label, x, si_unit, us_scale, us_unit):
    """A row of one quantity in SI and US units; "undefined" once where it is not a number."""
    x = float(x)
    if not math.isfinite(x):
        return _row(label, "undefined")
    return _row(label, f"{_fmt(x)} {si_unit}", f"{_fmt(x / us_scale)} {us_unit}")


LABEL_WIDTH, SI_WIDTH = 34, 26  # the label column's width and the SI column's least width: an ordinary panel's
GAP = 2  # the least number of spaces between two columns
WRAP_WIDTH = 100  # notes are wrapped to lines of at most this many characters


class _Row(NamedTuple):
    """One row of the panel: a label, its SI text and its US text ("" where the row has none), and a
    remark on it (``note``, "" for none) wrapped under it. The columns are laid out once the whole panel
    is known (``_layout``), so that wide numbers widen them."""
    label: str
    si: str
    us: str = ""
    note: str = ""


def _row(label, si, us="", note=""):
    return _Row(label, si, us, note)


def _wrapped(text, first="  ", then="    "):
    """``text`` wrapped to ``WRAP_WIDTH`` characters, its first line indented by ``first``, the rest by ``then``."""
    return "\n".join(textwrap.wrap(text, WRAP_WIDTH, initial_indent=first, subsequent_indent=then,
                                   break_on_hyphens=False))


UNITS = ("both", "si", "us")  # the panel's unit systems: SI beside US units, or one of them alone


def _in_units(row, units):
    """``row`` with the column of ``units`` alone ("si" or "us"; a row with no US text keeps its text, which
    is in units both systems use: degrees, seconds, words), or as it is ("both")."""
    if units == "both" or not row.us:
        return row
    return row._replace(si=row.si if units == "si" else row.us, us="")


def _layout(lines, units="both"):
    """The panel's text from its lines (text as it is, ``_Row``s in columns). The label column is
    ``LABEL_WIDTH`` wide: a longer label is wrapped within it, its first line beside the values and the
    rest under it, and a row's note is wrapped under the row, so that neither pushes the columns out. The
    SI column is as wide as its widest entry plus ``GAP`` spaces, and at least ``SI_WIDTH``, so that the
    US column starts at one offset in every row and never touches the SI text, whatever the numbers. An
    SI text with no US text beside it (a sentence) may run past its column and widens nothing."""
    lines = [_in_units(r, units) if isinstance(r, _Row) else r for r in lines]
    rows = [r for r in lines if isinstance(r, _Row)]
    si_width = max([SI_WIDTH] + [len(r.si) + GAP for r in rows if r.us])
    out = []
    for r in lines:
        if not isinstance(r, _Row):
            out.append(r)
            continue
        label, more = r.label, []
        if len(label) > LABEL_WIDTH - GAP:
            indent = len(label) - len(label.lstrip())
            label, *more = textwrap.wrap(label, LABEL_WIDTH - GAP, subsequent_indent=" " * (indent + 2),
                                         break_on_hyphens=False)
        out.append(f"  {label:<{LABEL_WIDTH}}{r.si:<{si_width}}{r.us}".rstrip())
        out += [f"  {line}" for line in more]
        if r.note:
            indent = " " * (4 + len(r.label) - len(r.label.lstrip()))
            out.append(_wrapped(r.note, indent, indent))
    return "\n".join(out)


def _timing_rows(sol):
    c = sol.result.contact
    if not (sol.case.auto_point or sol.case.auto_normal):
        return [_row("timing", "explicit contact: exchange at the case state")]
    dt = float(sol.case.inputs.contact.penetration_time)
    if sol.status == "no_contact":
        return [_row("first contact (timing)", f"none within {HORIZON:g} s of free motion")]
    return [_row("first contact (timing)", f"{_fmt(c.time, 4)} s"),
            _row("exchange (+ depth of penetration)", f"{_fmt(c.time + dt, 4)} s", f"(+{_fmt(dt, 4)} s)")]


def text_report(sol, reference: bool = True, units: str = "both") -> str:
    """The auto-ees panel of one solved case: SI beside US units (``units="both"``), or in one of them alone
    ("si" or "us"; angles in degrees and times in seconds either way)."""
    if units not in UNITS:
        raise ValueError(f"units = {units!r}: must be one of {', '.join(UNITS)}")
    lines = [f"Case: {visible(sol.case.name)}"]
    if sol.result is None or sol.status.startswith("invalid"):
        lines.append(f"  status: {sol.status}")
        return "\n".join(lines)
    c = sol.result.contact
    v1 = sol.result.vehicles[sol.case.between[0]]
    lines += ["", "  contact", _row("status", sol.status), *_timing_rows(sol)]
    if sol.case.vehicle_count + len(sol.case.fixed) > 2 or sol.case.between != (0, 1):
        lines.append(_row("between", " and ".join(f"{sol.case.body_path(b)} ({visible(sol.case.vehicle_names[b])})"
                                                 for b in sol.case.between)))
    if sol.status == "no_contact":  # no centroid, normal or closing speed: the exchange's are stand-ins
        lines.append(_row("impulse", "none (no contact)"))
    else:
        lines += _contact_rows(sol, c)
    lines += _vehicle_rows(sol)
    lines += _exchange_rows(sol)
    notes = [f"{visible(note)}." for note in sol.notes()]
    if sol.status == "no_contact":
        notes.append(f"the footprints do not touch within {HORIZON:g} s of free motion from the case state "
                     "(the search horizon): no exchange.")
    elif not np.isfinite(v1.ees) and c.energy_loss < 0:
        notes.append("EES is undefined: the energy loss is negative.")
    elif not np.isfinite(v1.ees):  # model.results.ees_pair: crushes of rounding size count as 0
        notes.append("EES is undefined: the centroid lies inside neither box (both crushes are 0).")
    lines += ["\n" + _wrapped(f"note: {note}", "  ", "        ") for note in notes]
    ref = sol.case.raw.get("reference") if reference else None
    if ref:
        lines += ["", reference_table(sol, ref)]
    return _layout(lines, units)


def _contact_rows(sol, c):
    return [
        _row("impulse centroid (x, y, z)", " ".join(_fmt(p) for p in c.point) + " m",
             " ".join(_fmt(p / U.FT) for p in c.point) + " ft"),
        _row("normal (azimuth, pitch)", f"{angle_text(math.degrees(math.atan2(c.normal[1], c.normal[0])))} deg, "
             f"{_fmt(math.degrees(math.asin(max(-1.0, min(1.0, float(c.normal[2]))))), 1)} deg"),
        _row("impulse", f"{_fmt(c.impulse_magnitude)} N s", f"{_fmt(c.impulse_magnitude / U.LBF_S)} lbf s"),
        _row("  normal / tangential", f"{_fmt(c.impulse_normal)} / {_fmt(c.impulse_tangential)} N s",
             f"{_fmt(c.impulse_normal / U.LBF_S)} / {_fmt(c.impulse_tangential / U.LBF_S)} lbf s"),
        _row("  azimuth / elevation", "undefined (no impulse)" if _no_impulse(sol)
             else f"{angle_text(c.impulse_azimuth, 2)} / {_fmt(c.impulse_elevation, 2)} deg"),
        _row("deformation energy (loss)", f"{_fmt(c.energy_loss)} J", f"{_fmt(c.energy_loss / U.FT_LBF, 2)} ft lbf"),
        _row("sliding at separation", "no impulse" if _no_impulse(sol) else "yes" if bool(c.sliding) else "no"),
        _row("closing speed at centroid", f"{_fmt(np.linalg.norm(c.closing_velocity))} m/s",
             f"{_fmt(np.linalg.norm(c.closing_velocity) / U.MPH, 2)} mph"),
        _row("separation speed at centroid", f"{_fmt(np.linalg.norm(c.separation_velocity))} m/s",
             f"{_fmt(np.linalg.norm(c.separation_velocity) / U.MPH, 2)} mph"),
    ]


def _vehicle_rows(sol):
    """Each vehicle's results of the first exchange (and its motion to rest), then each fixed object."""
    lines = []
    case = sol.case
    n = case.vehicle_count
    crush = sol.crush()
    for k, (name, v) in enumerate(zip(case.vehicle_names, sol.result.vehicles)):
        if k >= n:  # a fixed object has no per-vehicle results
            struck = k in case.between
            lines += ["", f"  fixed object: {visible(name)} = {case.body_path(k)}", f"  {describe(case.fixed[k - n])}",
                      "  (infinite mass, at rest" + (": vehicle 1 takes all of the first exchange's energy loss, EES = "
                                                      "sqrt(2 E / m))" if struck else ")")]
            continue
        if k not in case.between:
            lines += ["", f"  vehicles[{k}]: {visible(name)} (not in the first exchange)", *_hitch_rows(sol, k),
                      *_approach_rows(sol, k), *_crush_rows(crush[k])]
            if sol.result.rest is not None and sol.result.rest[k] is not None:
                lines += _rest_rows(sol.result.rest[k], case.motion)
            lines += _articulation_rows(sol, k)
            continue
        lines += [
            "",
            # as the output paths (sweeps, fits, --json) name it
            f"  vehicle {case.between.index(k) + 1} = vehicles[{k}]: {visible(name)}",
            *_hitch_rows(sol, k),
            *_approach_rows(sol, k),
            _row("delta-V", f"{_fmt(v.delta_v_magnitude)} m/s", f"{_fmt(v.delta_v_magnitude / U.MPH, 2)} mph"),
            _row("  longitudinal / lateral", f"{_fmt(v.delta_v_body[0])} / {_fmt(v.delta_v_body[1])} m/s",
                 f"{_fmt(v.delta_v_body[0] / U.MPH, 2)} / {_fmt(v.delta_v_body[1] / U.MPH, 2)} mph"),
            _row("PDOF", "undefined (no impulse)" if _no_impulse(sol) else "undefined" if not np.isfinite(v.pdof)
                 else f"{angle_text(v.pdof)} deg ({int(v.pdof_clock)} o'clock)"),
            *_joint_delta_v_rows(sol, k),
            _row(OVERLAP_LABEL, f"{_fmt(v.crush)} m", f"{_fmt(v.crush / U.FT)} ft"),
            _quantity(_ees_label(sol), defined_output(sol.result, f"vehicles[{k}].ees"), "m/s", U.MPH, "mph"),
            *_crush_rows(crush[k]),
            _row("speed after", f"{_fmt(v.speed_after)} m/s", f"{_fmt(v.speed_after / U.MPH, 2)} mph "
                 f"({_fmt(v.speed_after / U.FT, 2)} ft/s)"),
            _row("course after",
                 "undefined (at rest)" if bool(at_rest_after(v)) else f"{angle_text(v.course_after)} deg"),
            _row("yaw rate after", f"{_fmt(v.yaw_rate_after)} rad/s",
                 f"{_fmt(math.degrees(v.yaw_rate_after), 1)} deg/s"),
            _row("delta yaw rate", f"{_fmt(v.delta_yaw_rate)} rad/s",
                 f"{_fmt(math.degrees(v.delta_yaw_rate), 1)} deg/s"),
        ]
        if sol.result.rest is not None and sol.result.rest[k] is not None:
            lines += _rest_rows(sol.result.rest[k], sol.case.motion)
        lines += _articulation_rows(sol, k)
    return lines


# the exchange's crush: the depth of the centroid inside the vehicle's box, a model quantity (docs/model.md,
# "Crush energy"), not a measured crush
OVERLAP_LABEL = "crush, box overlap (model)"


def _ees_label(sol):
    """The EES row's label: how the energy loss was shared, where the case has crush profiles (by the vehicles'
    crush energies where both have one, else by the box overlap's crushes); "EES" alone where none has one."""
    if not sol.case.crush:
        return "EES"
    return "EES (by crush energy)" if sol.split_by_crush_energy() else "EES (by box overlap)"


def _crush_rows(crush: dict):
    """A vehicle's crush energy from its measured profile (``Solution.crush``), where it has one: the energy with its
    one-sigma uncertainty (where the case gives one), its EES and, for the first exchange's vehicles, the CRASH3
    delta-V."""
    energy, sigma = crush["crush_energy"], crush["crush_energy_sigma"]
    if energy is None:
        return []
    si, us = (f" +- {_fmt(sigma, 0)} J", f" +- {_fmt(sigma / U.FT_LBF, 0)} ft lbf") if sigma > 0 else (" J", " ft lbf")
    rows = [_row("crush energy (measured profile)", f"{_fmt(energy, 0)}{si}", f"{_fmt(energy / U.FT_LBF, 0)}{us}"),
            _quantity("  its EES", crush["crush_ees"], "m/s", U.MPH, "mph")]
    if crush["crush_delta_v"] is not None:
        rows.append(_quantity("  delta-V from crush (CRASH3)", crush["crush_delta_v"], "m/s", U.MPH, "mph"))
    return rows


HITCH_KINDS = {"drawbar": "drawbar", "fifth_wheel": "fifth wheel"}  # a hitch's kind as the panel words it


def _hitch_rows(sol, k):
    """Vehicle ``k``'s hitches (docs/model.md, "Articulated vehicles"): what tows it and how (the hitch's kind and
    its articulation limit), what it tows; then, where the joint moved it (``_joint_delta_v_rows``) and it took no
    part in the first exchange, its cumulative delta-V: a tractor whose trailer was struck."""
    case, rows = sol.case, []
    for (towed, tow, kind), hitch in zip(_links(case), case.inputs.hitches):
        if towed == k:
            limit = float(hitch.max_angle)
            limit = f"max {_fmt(math.degrees(limit), 1)} deg" if math.isfinite(limit) else "no articulation limit"
            rows.append(_row("hitch", f"towed by {_named(case, tow)}, {HITCH_KINDS.get(kind, kind)}; {limit}"))
        elif tow == k:
            rows.append(_row("hitch", f"tows {_named(case, towed)}, {HITCH_KINDS.get(kind, kind)}"))
    if k not in case.between:
        rows += _joint_delta_v_rows(sol, k)
    return rows


def _approach_rows(sol, k):
    """Vehicle ``k``'s approach (docs/model.md, "The approach"), where it has one: at the start of each phase, earliest
    first, the time before the impact, the speed and the CG's path from there to the impact."""
    approach = getattr(sol.result, "approach", None)
    if approach is None or k >= len(approach) or approach[k] is None:
        return []
    a = approach[k]
    rows = [_row("approach (each phase's start)", "time, speed, distance to the impact")]
    for p, (t, v, d) in enumerate(zip(np.atleast_1d(a.time), np.atleast_1d(a.speed), np.atleast_1d(a.distance))):
        if not all(math.isfinite(float(x)) for x in (t, v, d)):
            rows.append(_row(f"  approach[{p}]", "undefined"))
            continue
        rows.append(_row(f"  approach[{p}]", f"{_fmt(t)} s, {_fmt(v)} m/s, {_fmt(d)} m",
                         f"{_fmt(t)} s, {_fmt(v / U.MPH, 2)} mph, {_fmt(d / U.FT)} ft"))
    return rows


def _links(case):
    """The case's hitches, each ``(towed, tow, kind)`` (``Motion.links``; a hitch needs a road): none without one."""
    return case.motion.links if case.motion is not None else ()


def _named(case, b):
    """Body ``b`` as the panel names it: its path and its name, escaped."""
    return f"{case.body_path(b)} ({visible(case.vehicle_names[b])})"


def _joint_delta_v_rows(sol, k):
    """Where vehicle ``k`` is hitched and its cumulative delta-V differs from its first exchange's delta-V by what
    the panel shows (the joint's impulse right after the exchange moved it: a vehicle of the pair, or the other
    vehicle of the hitch), its cumulative delta-V and PDOF; none where the case had several exchanges, whose list
    ends with every vehicle's cumulative delta-V (``_exchange_rows``)."""
    inter = sol.result.interactions
    if not any(k in link[:2] for link in _links(sol.case)) or inter is None or int(inter.count) > 1:
        return []
    cumulative = np.asarray(inter.delta_v_cumulative[k], float)
    first = np.asarray(sol.result.vehicles[k].delta_v, float) if k in sol.case.between else np.zeros_like(cumulative)
    if not np.max(np.abs(cumulative - first)) >= 0.5e-3:  # rounds to what the delta-V row shows already
        return []
    dv = float(defined_output(sol.result, f"vehicles[{k}].delta_v_cumulative_magnitude"))
    pdof = float(defined_output(sol.result, f"vehicles[{k}].delta_v_cumulative_pdof"))
    pdof = f"PDOF {'undefined' if not math.isfinite(pdof) else angle_text(pdof) + ' deg'}"
    return [_row("cumulative delta-V (with hitch)", f"{_fmt(dv)} m/s, {pdof}", f"{_fmt(dv / U.MPH, 2)} mph, {pdof}")]


def _articulation_rows(sol, k):
    """Where vehicle ``k`` is towed and both it and its tow have a rest result: its articulation at rest (its rest
    yaw minus its tow's, in (-180, 180] deg)."""
    angle = sol.articulation_at_rest(k)
    if not math.isfinite(angle):
        return []
    angle = round(angle, 1)
    angle += 360.0 if angle <= -180.0 else 0.0  # as shown: -179.97 to one digit is 180.0, not -180.0
    return [_row("articulation at rest", f"{_fmt(angle, 1)} deg (its yaw minus its tow's)")]


def _exchange_rows(sol):
    """Where the case had more than one exchange: each exchange as the manual's "next contact" lists it (time, the
    pair, impulse, energy loss, each vehicle's delta-V and PDOF), then each vehicle's cumulative delta-V over its
    first contact interaction (docs/model.md, "Contact interactions")."""
    exchanges = sol.exchange_list()
    if len(exchanges) < 2:
        return []
    names = sol.body_names()
    n = sol.case.vehicle_count
    lines = ["", f"  exchanges ({len(exchanges)}; the manual's \"next contact\")"]
    # each row's SI and US columns are whole (a panel in one unit system shows one of them): the pair on a row of
    # its own, a PDOF beside the delta-V in both
    for ex in exchanges:
        pair = " and ".join(names[b if isinstance(b, int) else n + int(b[6:-1])][0] for b in ex["between"])
        j, e = ex["impulse_magnitude"], ex["energy_loss"]
        lines.append(_row(f"#{ex['index']} at {_fmt(ex['time'])} s, interaction {ex['interaction']}", pair))
        lines.append(_row("    impulse, energy", f"{_fmt(j)} N s, {_fmt(e)} J",
                          f"{_fmt(j / U.LBF_S)} lbf s, {_fmt(e / U.FT_LBF)} ft lbf"))
        for v in ex["vehicles"]:
            pdof = "PDOF undefined" if v["pdof"] is None else f"PDOF {angle_text(v['pdof'])} deg"
            dv = v["delta_v_magnitude"]
            lines.append(_row(f"    vehicles[{v['vehicle']}] delta-V", f"{_fmt(dv)} m/s, {pdof}",
                              f"{_fmt(dv / U.MPH, 2)} mph, {pdof}"))
    joints = ", the hitches' impulses" if _links(sol.case) else ""
    lines += ["", _wrapped(f"cumulative delta-V (first contact interaction, tyre forces between exchanges{joints} "
                           "included)", "  ", "  ")]
    for k in range(n):
        dv = float(defined_output(sol.result, f"vehicles[{k}].delta_v_cumulative_magnitude"))
        pdof = float(defined_output(sol.result, f"vehicles[{k}].delta_v_cumulative_pdof"))
        pdof = f"PDOF {'undefined' if not math.isfinite(pdof) else angle_text(pdof) + ' deg'}"
        lines.append(_row(f"vehicles[{k}]", f"{_fmt(dv)} m/s, {pdof}", f"{_fmt(dv / U.MPH, 2)} mph, {pdof}"))
    return lines


def _rest_rows(r, motion):
    """A vehicle's motion to rest (``model.motion.RestResult``): where and when it stops."""
    x, y = (float(p) for p in r.rest_position)
    moving = "" if bool(r.at_rest) else f"still moving at the time limit ({motion.time_limit:g} s): where it is then"
    return [
        _row(f"rest position (x, y){'' if moving else ': at rest'}", f"{_fmt(x)} {_fmt(y)} m",
             f"{_fmt(x / U.FT)} {_fmt(y / U.FT)} ft", note=moving),
        _row("rest yaw (turned to rest)", f"{angle_text(r.rest_yaw)} deg ({_fmt(r.rotation_to_rest, 1)} deg)"),
        _row("time to rest", f"{_fmt(r.time_to_rest)} s"),
        _row("distance to rest (CG path)", f"{_fmt(r.distance_to_rest)} m", f"{_fmt(r.distance_to_rest / U.FT)} ft"),
    ]


def reference_table(sol, reference: dict) -> str:
    """Reported values (e.g. the manual's panel) beside ks-jax's, in the reported units; the difference
    in percent, or in degrees for a direction (on the circle: 359 against 1 is 2 degrees apart). Each
    column is as wide as its widest entry plus ``GAP`` spaces, and at least 39, 20 and 20 characters."""
    rows = [("reference", "reported", "ks-jax", "difference")]
    for path, value in reference.items():
        want_si = parse_output_value(value, path, sol.case.name, f"reference.{path}")
        got_si = float(np.asarray(defined_output(sol.result, path)))
        parts = value.split(None, 1) if isinstance(value, str) else []
        unit = parts[1] if len(parts) == 2 else ""
        scale = want_si / float(parts[0]) if unit and float(parts[0]) != 0 else 1.0
        got, want = got_si / scale, want_si / scale
        if not math.isfinite(got):
            diff = "undefined"
        elif parse_path(path)[2] in CIRCULAR_OUTPUTS:
            diff = f"{(got_si - want_si + 180.0) % 360.0 - 180.0:+.4f} deg"
        else:
            diff = f"{(got - want) / want * 100:+.4f} %" if want else f"{got - want:+.4f}"
        rows.append((path, f"{_fmt(want, 3)} {unit}".rstrip(), f"{_fmt(got, 3)} {unit}".rstrip(), diff))
    widths = [max([least] + [len(r[k]) + GAP for r in rows]) for k, least in enumerate((39, 20, 20))]
    return "\n".join(("  " + "".join(f"{text:<{w}}" for text, w in zip(r, widths)) + r[3]).rstrip() for r in rows)
