"""Named unit constants and conversions (docs/model.md, "Units and frames").

Everything inside ks_jax is SI (m, kg, s, N, J, rad). This module is the only place
that knows about feet, pounds and miles per hour. Multiply by a constant to go to SI,
divide to come back: ``21 * MPH`` is 21 mph in m/s, ``v / MPH`` is v in mph.

Unit strings in case files ("21 mph", "3496.531 lbf", "2300 lbf*ft*s^2") are parsed by
:func:`parse_quantity`, which uses pint (the ``units`` extra) and checks the dimension.
"""

from __future__ import annotations

import datetime
import difflib
import math
import re
from functools import lru_cache

# exact definitions
FT = 0.3048  # m
INCH = 0.0254  # m
MILE = 1609.344  # m
MPH = MILE / 3600.0  # m/s
KPH = 1000.0 / 3600.0  # m/s
FPS = FT  # ft/s in m/s
G0 = 9.80665  # m/s^2, standard gravity
G0_FT = G0 / FT  # 32.174... ft/s^2
LB = 0.45359237  # kg (pound mass)
LBF = LB * G0  # N (pound force)
SLUG = LBF / FT  # kg (lbf s^2 / ft)
LBF_S = LBF  # N s
FT_LBF = FT * LBF  # J
DEG = math.pi / 180.0  # rad
DEG_S = DEG  # rad/s per deg/s

# The dimension each kind of input must have, as pint writes it.
DIMENSIONS = {
    "length": "[length]",
    "mass": "[mass]",
    "force": "[length] * [mass] / [time] ** 2",
    "inertia": "[length] ** 2 * [mass]",
    "velocity": "[length] / [time]",
    "time": "[time]",
    "angle": "",
    "angular_velocity": "1 / [time]",
    "dimensionless": "",
    "impulse": "[length] * [mass] / [time]",
    "energy": "[length] ** 2 * [mass] / [time] ** 2",
    "force_per_length": "[mass] / [time] ** 2",  # a crush stiffness A (force per unit of damage width)
    "force_per_area": "[mass] / [length] / [time] ** 2",  # a crush stiffness B (per unit of width and of crush)
}

# SI unit each kind is converted to; angles go to radians, angular velocity to rad/s.
SI_UNITS = {
    "length": "m",
    "mass": "kg",
    "force": "N",
    "inertia": "kg*m^2",
    "velocity": "m/s",
    "time": "s",
    "angle": "rad",
    "angular_velocity": "rad/s",
    "dimensionless": "",
    "impulse": "N*s",
    "energy": "J",
    "force_per_length": "N/m",
    "force_per_area": "N/m^2",
}

# What a bare number means, per kind: SI, except angles (degrees) and angular velocities (deg/s).
BARE_NUMBER_SCALE = {"angle": DEG, "angular_velocity": DEG_S}


# How a quantity of each kind is shown to a reconstructionist (plots): (SI value of one display unit,
# its label). "degrees": results already reported in degrees (docs/model.md, "Results").
US_DISPLAY = {
    "length": (FT, "ft"),
    "mass": (LB, "lb"),
    "force": (LBF, "lbf"),
    "inertia": (SLUG * FT**2, "lbf ft s^2"),
    "velocity": (MPH, "mph"),
    "time": (1.0, "s"),
    "angle": (DEG, "deg"),
    "angular_velocity": (DEG_S, "deg/s"),
    "dimensionless": (1.0, ""),
    "impulse": (LBF_S, "lbf s"),
    "energy": (FT_LBF, "ft lbf"),
    "force_per_length": (LBF / INCH, "lbf/in"),
    "force_per_area": (LBF / INCH**2, "lbf/in^2"),
    "degrees": (1.0, "deg"),
}


# The same in SI units (``--units si``): the quantities' SI units, except directions and rates, which are drawn in
# degrees and deg/s in either system, as reconstructionists read them (and write them, as bare numbers).
SI_DISPLAY = {
    "length": (1.0, "m"),
    "mass": (1.0, "kg"),
    "force": (1.0, "N"),
    "inertia": (1.0, "kg m^2"),
    "velocity": (1.0, "m/s"),
    "time": (1.0, "s"),
    "angle": (DEG, "deg"),
    "angular_velocity": (DEG_S, "deg/s"),
    "dimensionless": (1.0, ""),
    "impulse": (1.0, "N s"),
    "energy": (1.0, "J"),
    "force_per_length": (1.0, "N/m"),
    "force_per_area": (1.0, "N/m^2"),
    "degrees": (1.0, "deg"),
}
DISPLAY = {"si": SI_DISPLAY, "us": US_DISPLAY}


def display_unit(kind, units="si", typed=None):
    """(SI value of one display unit, its label) for a quantity of ``kind`` shown in the ``units`` system
    ("si" or "us"), or in the unit ``typed`` where one was given ("km/h": the unit of a value the user
    typed, ``typed_unit``; the label is the unit as typed)."""
    if typed:
        return parse_quantity(f"1 {typed}", kind), typed
    if units not in DISPLAY:
        raise UnitError(f"units = {units!r}: must be 'si' or 'us'")
    return DISPLAY[units][kind]


def typed_unit(text):
    """The unit of a typed quantity ("10km/h" -> "km/h", "21 mph" -> "mph"), or None for a bare number or
    anything that is not one number and its unit."""
    if not isinstance(text, str):
        return None
    match = _QUANTITY.match(text.strip())
    unit = " ".join(match.group(2).split()) if match else ""
    return unit or None


def as_typed(value) -> str:
    """A value read from a case file, for a message, as the file wrote it: null, true and false as JSON and TOML
    write them, a TOML date or time in its own form, lists and tables of them likewise, anything else as
    ``repr``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (datetime.date, datetime.time)):  # a datetime is a date
        return f"{value.isoformat()} (a TOML date or time)"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(as_typed(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k!r}: {as_typed(v)}" for k, v in value.items()) + "}"
    return repr(value)


class UnitError(ValueError):
    """A quantity string that cannot be read, or has the wrong dimension."""


# A folder where pint keeps its unit definitions, parsed, between runs (pint's ``cache_folder``), or None:
# parse them in every process. ``compilation.keep_programs`` sets it (the command line calls it) before the first
# unit string is read: reading the parsed definitions back is several times faster than parsing them.
REGISTRY_CACHE = None


@lru_cache(maxsize=1)
def _registry():
    try:
        import pint
    except ImportError as err:  # pragma: no cover - exercised only without the extra
        raise UnitError(
            "unit strings need pint: pip install 'ks-jax[units]' (or give bare SI numbers)"
        ) from err
    if REGISTRY_CACHE is not None:
        try:
            return pint.UnitRegistry(cache_folder=str(REGISTRY_CACHE))
        except Exception:  # noqa: BLE001 - a folder that cannot be read or written: parse the definitions
            pass
    return pint.UnitRegistry()


_NUMBER = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_QUANTITY = re.compile(rf"^({_NUMBER})\s*(.*)$")
_EXPONENT = re.compile(r"(?:\^|\*\*)\s*\(?\s*[+-]?\d+(?:\.\d+)?\s*\)?")
_UNIT_TEXT = re.compile(r"^[^\W\d]*(?:[^\W\d]|[\s*/()·²³¹⁰⁻])*$")
_HYPHEN = re.compile(r"(?<=[^\W\d])-(?=[^\W\d])")  # ft-lbf, lbf-s: a product, as the trade writes it
_FORM = ("write one number, then its unit (no thousands separator, a decimal point rather than a comma, "
         "nothing after the unit)")


def _split(text):
    """(number, unit) of a '<number> <unit>' string, the unit made ready for pint ('ft-lbf' -> 'ft*lbf');
    UnitError for anything else, so that "1 500 kg", "4,5 m" or "30 mph 2" are refused rather than read
    as pint would read them (500 kg, 45 m, 60 mph)."""
    m = _QUANTITY.match(text)
    if not m:
        raise UnitError(f"'{text}' is not a '<number> <unit>' quantity: {_FORM}")
    number, unit = m.groups()
    unit = _HYPHEN.sub("*", unit)
    bare = _EXPONENT.sub("", re.sub(r"^1\s*/", "/", unit))  # exponents and a leading "1/" hold the only digits
    if not _UNIT_TEXT.match(bare):
        raise UnitError(f"'{text}' is not a '<number> <unit>' quantity: {_FORM}")
    return number, unit


def _names_an_angle(ureg, q):
    """Whether a rate's unit holds an angle (deg/s, rad/s, rpm, turn/min), not only a time (1/s, Hz)."""
    for name, _ in q.unit_items():
        unit = ureg.Quantity(1, name)
        if (unit.dimensionless and not unit.unitless) or "revolution" in name:
            return True
    return False


def parse_quantity(value, kind: str) -> float:
    """A number (SI, or degrees / deg/s for angles and rates) or a "<number> <unit>" string,
    returned as a float in the SI unit of ``kind`` (see ``SI_UNITS``).

    The string is one number and its unit: "21 mph", "3496.531 lbf", "2300 lbf*ft*s^2", "14117.71 ft-lbf"
    (a hyphen between unit names is a product). Refused: anything after or inside the number ("1 500 kg",
    "4,5 m", "30 mph 2"), a unit of another dimension, an angle unit on a plain number (restitution,
    friction), and a rate without an angle ("1 Hz", "2 1/s": write deg/s, rad/s or rpm).
    Raises UnitError with the rule that failed.
    """
    if kind not in SI_UNITS:
        raise KeyError(kind)
    if isinstance(value, bool):
        raise UnitError(f"{as_typed(value)} is not a number or a '<number> <unit>' string")
    if isinstance(value, (int, float)):
        try:
            return float(value) * BARE_NUMBER_SCALE.get(kind, 1.0)
        except OverflowError:  # an integer beyond any float
            raise UnitError(f"an integer of about {int(value.bit_length() * 0.30103) + 1} digits is larger than "
                            "any finite number") from None
    if not isinstance(value, str):
        raise UnitError(f"{as_typed(value)} is not a number or a '<number> <unit>' string")
    text = value.strip()
    try:
        return float(text) * BARE_NUMBER_SCALE.get(kind, 1.0)
    except ValueError:
        pass
    if "°" in text:
        raise UnitError(f"'{text}': write the degree sign as deg: '{text.replace('°', ' deg').replace('  ', ' ')}'")
    number, unit = _split(text)
    if not unit:
        return float(number) * BARE_NUMBER_SCALE.get(kind, 1.0)
    ureg = _registry()
    import pint

    try:
        q = ureg.Quantity(float(number), unit)
    except (pint.errors.UndefinedUnitError, pint.errors.DefinitionSyntaxError) as err:
        close = difflib.get_close_matches(unit, COMMON_UNITS.get(kind, ()), n=1, cutoff=0.5)
        hint = f": did you mean '{number} {close[0]}'?" if close else ""
        raise UnitError(f"'{text}': unknown unit ({err}){hint}") from None
    except Exception as err:  # noqa: BLE001 (pint raises several kinds for malformed text)
        raise UnitError(f"'{text}' is not a '<number> <unit>' quantity ({err})") from None
    if kind == "dimensionless":
        if not q.unitless:
            raise UnitError(f"'{text}': a {kind} number takes no unit (give a plain number)")
        return float(q.to("").magnitude)
    if kind == "angle" and q.dimensionless:
        if dict(q.to_root_units().unit_items()) != {"radian": 1}:  # a solid angle (sr), a percent, ...
            raise UnitError(f"'{text}': an angle needs a plane-angle unit (deg, rad, turn, arcmin); "
                            f"'{unit}' is not one")
        return float(q.to(SI_UNITS[kind]).magnitude)
    if kind == "angular_velocity" and q.dimensionality == ureg.Quantity(1, "1/s").dimensionality \
            and not _names_an_angle(ureg, q):
        raise UnitError(f"'{text}': an angular velocity needs an angle in its unit (deg/s, rad/s, rpm); "
                        f"'{unit}' does not say whether it counts radians or turns")
    try:
        return float(q.to(SI_UNITS[kind]).magnitude)
    except pint.errors.DimensionalityError:
        close = difflib.get_close_matches(unit, COMMON_UNITS.get(kind, ()), n=1, cutoff=0.5)
        raise UnitError(
            f"'{text}' has the dimension {q.dimensionality}, not that of {'an' if kind[0] in 'aeiou' else 'a'} "
            f"{kind.replace('_', ' ')}"
            f" ({SI_UNITS[kind] or 'dimensionless'})" + (f": did you mean '{number} {close[0]}'?" if close else "")
        ) from None


# Units a reconstructionist writes for each kind: a unit of another dimension is matched against these for a
# suggestion ("21 mhp" reads as milli-horsepower: did you mean mph?)
COMMON_UNITS = {
    "length": ("m", "cm", "mm", "km", "ft", "in", "yd", "mi"),
    "mass": ("kg", "g", "lb", "slug", "t"),
    "force": ("N", "kN", "lbf", "kgf"),
    "velocity": ("mph", "km/h", "kph", "m/s", "ft/s", "knot"),
    "angle": ("deg", "rad", "turn", "arcmin"),
    "angular_velocity": ("deg/s", "rad/s", "rpm"),
    "inertia": ("kg*m^2", "lbf*ft*s^2", "slug*ft^2"),
    "energy": ("J", "kJ", "ft*lbf"),
    "impulse": ("N*s", "lbf*s"),
    "time": ("s", "ms"),
    "force_per_length": ("N/m", "kN/m", "lbf/in"),
    "force_per_area": ("N/m^2", "kN/m^2", "lbf/in^2"),
}
MAX_TURNS = 1e6  # an orientation given in radians or turns beyond this many turns is refused


def parse_orientation(value) -> float:
    """An orientation angle (``parse_quantity`` of kind "angle"), as radians within one turn either side of 0.
    In degrees (a bare number, or a degree unit) it is reduced modulo 360 exactly, before any rounding: 1e20
    deg is 280 deg. In another unit a value beyond ``MAX_TURNS`` turns is refused: its conversion to degrees
    has already rounded away the orientation (float64 holds 1e20 rad only to the nearest 16384 rad)."""
    x = parse_quantity(value, "angle")
    degrees = value if isinstance(value, (int, float)) else _degrees_given(value)
    if degrees is not None and math.isfinite(degrees):
        return math.fmod(float(degrees), 360.0) * DEG
    if not math.isfinite(x):
        return x  # refused by the caller, which names the field
    if not abs(x) <= MAX_TURNS * 2.0 * math.pi:
        raise UnitError(f"'{value}': {abs(x) / (2 * math.pi):.3g} turns; an orientation this large has no meaning "
                        "in floating point: give it within a turn, or in degrees")
    return math.fmod(x, 2.0 * math.pi)


def _degrees_given(text):
    """The number of degrees of a "<number> deg" string (deg, degree, degrees, °), None for another unit."""
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(deg|degree|degrees)?\s*", str(text))
    return float(m.group(1)) if m else None


def to_mph(v):
    """m/s -> mph."""
    return v / MPH


def to_ft(x):
    """m -> ft."""
    return x / FT


def to_lbf_s(j):
    """N s -> lbf s."""
    return j / LBF_S


def to_ft_lbf(e):
    """J -> ft lbf."""
    return e / FT_LBF
