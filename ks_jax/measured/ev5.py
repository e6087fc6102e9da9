"""NHTSA crash-test files: the EV5 descriptor of a test and its ASCII channel files (docs/measured.md).

A test downloaded from the NHTSA Vehicle Crash Test Database in its ASCII form is a folder holding
``v<test>.EV5`` and one file per channel (curve), ``v<test>.<curve, 3 digits>``, side by side.

The EV5 is pipe-delimited text in sections, each opened by a line ``----- NAME -----`` (``EV5``, ``TEST``,
``VEHICLE``, ``BARRIER``, ``OCCUPANT``, ``RESTRAINT``, ``INSTRUMENTATION``, ``END``; lines starting ``#`` are
comments). The fields this module reads, by position (0-based), as checked against NHTSA's JSON of test 7292,
which names every field (docs/validation/nhtsa/SOURCES.md):

- TEST, one record: 1 TITLE, 8 TSTCFN (configuration: VTV vehicle into vehicle, VTB vehicle into barrier, ...),
  14 CLSSPD (closing speed, km/h), 15 IMPANG (impact angle, deg), 18 TOTCRV (number of curves).
- VEHICLE, one record per vehicle: 0 VEHNO, 1 MAKE (code), 2 MODEL (code), 3 YEAR, 10 VEHTWT (test mass, kg),
  12 WHLBAS, 13 VEHLEN, 14 VEHWID, 15 VEHCG (CG behind the front axle) (mm), 41 VEHSPD (km/h), 42 CRBANG
  (crab angle, deg), 43 PDOF (deg), 47-52 DPD1-DPD6 (crush depths, mm).
- INSTRUMENTATION, one record per curve: 0 VEHNO, 1 CURNO, 2 SENTYP, 3 SENLOC, 4 SENATT, 5 AXIS, 6 XUNITS,
  7 YUNITS, 8 PREFIL (Hz), 9 INSMAN, 10 CALDAT, 11 INSRAT, 12 CHLMAX, 13 INIVEL (initial velocity along the
  axis, km/h), 14 NFP, 15 NLP (first and last point), 16 DELT (sample interval, microseconds), 17 DASTAT (data
  status: AM as measured), 18 CHSTAT (P primary, R redundant), 19 INSCOM.

A channel file has no header: rows of two columns separated by tabs, the time in seconds and the value in the
curve's YUNITS (G'S for accelerometers); it holds NLP - NFP + 1 rows, row k at time (NFP + k) DELT. Vehicle
sensor axes (XG, YG, ZG) are the vehicle's SAE J211 axes: x forward, y right, z down.

Everything in the dataclasses is SI (m, kg, s, m/s, Hz), except the angles the EV5 records, kept in degrees
as recorded. Bad input is refused with a ValueError naming the file, the field, its value and the rule.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ks_jax.units import DEG, DEG_S, G0, KPH

MM = 1e-3  # m
US = 1e-6  # s

# A channel's YUNITS -> the SI value of one unit (values are multiplied by it)
UNITS = {"G'S": G0, "NWT": 1.0, "NWM": 1.0, "MM": MM, "DEG": DEG, "DPS": DEG_S, "SEC": 1.0}

SECTION = re.compile(r"^-{3,}\s*([A-Z0-9]+)\s*-{3,}$")
REQUIRED = ("TEST", "VEHICLE", "INSTRUMENTATION", "END")

TEST_FIELDS = 19  # VERNO .. TOTCRV (TSTCOM, the 20th, may be missing)
VEHICLE_FIELDS = 80  # VEHNO .. VEHOR (VEHCOM, the 81st, may be missing)
INSTRUMENTATION_FIELDS = 19  # VEHNO .. CHSTAT (INSCOM, the 20th, may be missing)


@dataclass(frozen=True)
class TestVehicle:
    """One VEHICLE record. number: VEHNO (1 the bullet or the barrier test's vehicle, 2 the target); year,
    make, model: as given (make and model are NHTSA codes); mass (kg); wheelbase, length, width, cg_behind_front_axle
    (m); speed (m/s); crab_angle, pdof (deg, as recorded); crush: DPD1-DPD6 (m, None where the field is empty)."""

    number: int
    year: str
    make: str
    model: str
    mass: float | None
    wheelbase: float | None
    length: float | None
    width: float | None
    cg_behind_front_axle: float | None
    speed: float | None
    crab_angle: float | None
    pdof: float | None
    crush: tuple


@dataclass(frozen=True)
class Channel:
    """One INSTRUMENTATION record and the path of its file. curve: CURNO; vehicle: VEHNO (0 the barrier);
    sensor: SENTYP (AC accelerometer, LC load cell, ...); location: SENLOC; attachment: SENATT (VECG the vehicle's
    CG, FLLR / FLRR left / right rear-seat crossmember, ...); axis: AXIS (XG, YG, ZG vehicle axes); units: YUNITS;
    prefilter (Hz); initial_velocity (m/s, along the axis); first, last: NFP, NLP; dt: DELT (s); status: DASTAT
    (AM as measured); role: CHSTAT (P primary, R redundant); comment: INSCOM; path: the channel file."""

    curve: int
    vehicle: int
    sensor: str
    location: str
    attachment: str
    axis: str
    units: str
    prefilter: float | None
    initial_velocity: float | None
    first: int
    last: int
    dt: float
    status: str
    role: str
    comment: str
    path: Path


@dataclass(frozen=True)
class CrashTest:
    """An EV5 file. number: the test number (from the file name v<number>.EV5); title; configuration: TSTCFN
    (VTV, VTB, ...); closing_speed (m/s); impact_angle (deg, IMPANG as recorded); barrier: the BARRIER record's
    fields, () where there is none; vehicles: ``TestVehicle`` per VEHICLE record; channels: ``Channel`` per
    INSTRUMENTATION record; path: the EV5 file."""

    number: int
    title: str
    configuration: str
    closing_speed: float | None
    impact_angle: float | None
    barrier: tuple
    vehicles: tuple
    channels: tuple
    path: Path

    def vehicle(self, number: int) -> TestVehicle:
        """The VEHICLE record of VEHNO ``number``; ValueError naming the numbers there are."""
        for v in self.vehicles:
            if v.number == number:
                return v
        raise ValueError(f"{self.path}: VEHICLE: VEHNO = {number!r}: no such vehicle (the test has "
                         f"{', '.join(str(v.number) for v in self.vehicles)})")


class _Record:
    """One pipe-delimited line of a section, with its place in the file, for messages."""

    def __init__(self, path, line_no, section, fields):
        self.path, self.line_no, self.section, self.fields = path, line_no, section, fields

    def where(self, index, name):
        return f"{self.path}: line {self.line_no} ({self.section}), field {index} {name}"

    def text(self, index, name):
        return self.fields[index].strip() if index < len(self.fields) else ""

    def number(self, index, name, scale=1.0, required=False, nonnegative=False):
        raw = self.text(index, name)
        if raw == "":
            if required:
                raise ValueError(f"{self.where(index, name)} is empty: must be a number")
            return None
        try:
            x = float(raw)
        except ValueError:
            raise ValueError(f"{self.where(index, name)} = {raw!r}: must be a number") from None
        if not math.isfinite(x):
            raise ValueError(f"{self.where(index, name)} = {raw!r}: must be a finite number")
        if nonnegative and x < 0:
            raise ValueError(f"{self.where(index, name)} = {raw!r}: must not be negative")
        return x * scale

    def integer(self, index, name):
        raw = self.text(index, name)
        try:
            return int(raw)
        except ValueError:
            raise ValueError(f"{self.where(index, name)} = {raw!r}: must be a whole number") from None


def _sections(path: Path, text: str) -> dict:
    """{section name: [_Record]} of an EV5's text; ValueError for a record outside a section or a section missing."""
    sections, name = {}, None
    for line_no, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        m = SECTION.match(stripped)
        if m:
            name = m.group(1)
            sections.setdefault(name, [])
            continue
        if name is None:
            raise ValueError(f"{path}: line {line_no} = {stripped[:60]!r}: a record before any section header "
                             "(an EV5 starts with '----- EV5 -----' or '----- TEST -----')")
        sections[name].append(_Record(path, line_no, name, line.split("|")))
    for required in REQUIRED:
        if required not in sections:
            raise ValueError(f"{path}: section {required}: missing (an EV5 has the sections "
                             f"{', '.join(REQUIRED)}, each opened by '----- NAME -----')")
    return sections


def _count(record: _Record, least: int):
    if len(record.fields) < least:
        raise ValueError(f"{record.path}: line {record.line_no} ({record.section}): {len(record.fields)} fields: "
                         f"must have at least {least} pipe-separated fields")


def _test_number(path: Path) -> int:
    stem = path.stem
    if len(stem) > 1 and stem[0] in "vV" and stem[1:].isdigit():
        return int(stem[1:])
    raise ValueError(f"{path}: file name {path.name!r}: must be v<test number>.EV5 (as NHTSA names it; its "
                     "channel files are v<test number>.<curve>)")


def _vehicle(r: _Record) -> TestVehicle:
    _count(r, VEHICLE_FIELDS)
    crush = tuple(r.number(47 + k, f"DPD{k + 1}", MM) for k in range(6))
    return TestVehicle(
        number=r.integer(0, "VEHNO"), make=r.text(1, "MAKE"), model=r.text(2, "MODEL"), year=r.text(3, "YEAR"),
        mass=r.number(10, "VEHTWT", nonnegative=True), wheelbase=r.number(12, "WHLBAS", MM, nonnegative=True),
        length=r.number(13, "VEHLEN", MM, nonnegative=True), width=r.number(14, "VEHWID", MM, nonnegative=True),
        cg_behind_front_axle=r.number(15, "VEHCG", MM), speed=r.number(41, "VEHSPD", KPH),
        crab_angle=r.number(42, "CRBANG"), pdof=r.number(43, "PDOF"), crush=crush)


def _channel(r: _Record, folder: Path, stem: str) -> Channel:
    _count(r, INSTRUMENTATION_FIELDS)
    curve = r.integer(1, "CURNO")
    first, last = r.integer(14, "NFP"), r.integer(15, "NLP")
    if last < first:
        raise ValueError(f"{r.where(15, 'NLP')} = {last}: must not be below NFP = {first}")
    dt = r.number(16, "DELT", US, required=True)
    if not dt > 0:
        raise ValueError(f"{r.where(16, 'DELT')} = {r.text(16, 'DELT')!r}: must be positive (microseconds)")
    return Channel(
        curve=curve, vehicle=r.integer(0, "VEHNO"), sensor=r.text(2, "SENTYP"), location=r.text(3, "SENLOC"),
        attachment=r.text(4, "SENATT"), axis=r.text(5, "AXIS"), units=r.text(7, "YUNITS"),
        prefilter=r.number(8, "PREFIL"), initial_velocity=r.number(13, "INIVEL", KPH), first=first, last=last,
        dt=dt, status=r.text(17, "DASTAT"), role=r.text(18, "CHSTAT"), comment="|".join(r.fields[19:]).strip(),
        path=folder / f"{stem}.{curve:03d}")


def read_test(path) -> CrashTest:
    """The EV5 file at ``path`` (a ``v<test>.EV5`` beside its channel files), read into a ``CrashTest``.

    ValueError naming the file, the line and field, the value and the rule, for a missing file, a missing
    section, a record with too few fields, a number that does not read, a negative mass or dimension, or two
    records of one vehicle or one curve."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file (give the test's v<number>.EV5)")
    number = _test_number(path)
    sections = _sections(path, path.read_text(encoding="latin-1"))
    tests = sections["TEST"]
    if len(tests) != 1:
        raise ValueError(f"{path}: section TEST: {len(tests)} records: must hold exactly one")
    t = tests[0]
    _count(t, TEST_FIELDS)
    vehicles = tuple(_vehicle(r) for r in sections["VEHICLE"])
    channels = tuple(_channel(r, path.parent, path.stem) for r in sections["INSTRUMENTATION"])
    for kind, items, key in (("VEHICLE", vehicles, "number"), ("INSTRUMENTATION", channels, "curve")):
        seen = [getattr(x, key) for x in items]
        twice = sorted({k for k in seen if seen.count(k) > 1})
        if twice:
            field = "VEHNO" if kind == "VEHICLE" else "CURNO"
            raise ValueError(f"{path}: section {kind}: {field} = {twice[0]}: given twice (one record each)")
    barrier = tuple(tuple(f.strip() for f in r.fields) for r in sections.get("BARRIER", []))
    return CrashTest(number=number, title=t.text(1, "TITLE"), configuration=t.text(8, "TSTCFN"),
                     closing_speed=t.number(14, "CLSSPD", KPH), impact_angle=t.number(15, "IMPANG"),
                     barrier=barrier, vehicles=vehicles, channels=channels, path=path)


def read_channel(channel: Channel) -> tuple:
    """(time (n,) s, values (n,) SI) of a channel's file: G'S times standard gravity G0 (m/s^2), mm to m,
    degrees to radians, newtons as they are.

    ValueError naming the file for a missing file, a row that is not two numbers, a row count other than
    NLP - NFP + 1, a time off (NFP + k) DELT by more than 1 % of DELT (plus a microsecond, the files' last digit),
    or units this module does not know."""
    path = channel.path
    if channel.units not in UNITS:
        raise ValueError(f"{path}: YUNITS = {channel.units!r} (curve {channel.curve}): unknown units (known: "
                         f"{', '.join(sorted(UNITS))})")
    if not path.is_file():
        raise ValueError(f"{path}: no such file (curve {channel.curve}'s channel file, beside the EV5)")
    lines = path.read_text(encoding="latin-1").splitlines()
    rows = []
    for line_no, line in enumerate(lines, 1):
        if not line.strip():
            continue
        parts = line.split()
        try:
            if len(parts) != 2:
                raise ValueError
            t, x = float(parts[0]), float(parts[1])
            if not (math.isfinite(t) and math.isfinite(x)):
                raise ValueError
        except ValueError:
            raise ValueError(f"{path}: line {line_no} = {line[:60]!r}: must be two finite numbers, time (s) and "
                             f"value ({channel.units}), separated by a tab") from None
        rows.append((t, x))
    expected = channel.last - channel.first + 1
    if len(rows) != expected:
        raise ValueError(f"{path}: {len(rows)} rows: must be NLP - NFP + 1 = {channel.last} - ({channel.first}) + 1 "
                         f"= {expected} (curve {channel.curve}'s INSTRUMENTATION record)")
    data = np.array(rows, dtype=np.float64)
    time, values = data[:, 0], data[:, 1]
    ideal = (channel.first + np.arange(expected)) * channel.dt
    off = np.flatnonzero(np.abs(time - ideal) > 0.01 * channel.dt + US)
    if off.size:
        k = int(off[0])
        raise ValueError(f"{path}: row {k + 1}: time = {time[k]:.9g} s: must be (NFP + k) DELT = "
                         f"{ideal[k]:.9g} s within 1 % of DELT = {channel.dt / US:g} microseconds (+ 1 "
                         f"microsecond): the sample interval disagrees with curve {channel.curve}'s record")
    return time, values * UNITS[channel.units]
