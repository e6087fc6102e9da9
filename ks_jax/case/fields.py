"""Reading one field of a case file: numbers and vectors with their units, tables and their keys, and the
words of the messages (the case, the field, the value as typed and in SI, the rule). Shared by ``load`` and
``hitch``; every error is a ``CaseError``."""

from __future__ import annotations

import math
import warnings

from .. import units as U
from .errors import CaseError, CaseWarning, visible


def where(case_name, path):
    """Where a message points: the case (its name as the terminal shows it, ``visible``) and the field."""
    return f"case '{visible(case_name)}': {path}"


def number(value, kind, path, case_name, orientation=True):
    """A field's number, SI (``units.parse_quantity``): an angle is an orientation (``units.parse_orientation``:
    reduced to within a turn) unless ``orientation`` is False (a size, such as a largest angle)."""
    if isinstance(value, LongInteger):
        raise CaseError(f"{where(case_name, path)} = {value[:20]}... (an integer of "
                        f"{len(value.lstrip('-'))} digits): larger than any finite number")
    try:
        x = U.parse_orientation(value) if kind == "angle" and orientation else U.parse_quantity(value, kind)
    except U.UnitError as err:
        raise CaseError(f"{where(case_name, path)} = {shown(value)}: {err}") from None
    if not math.isfinite(x):
        raise CaseError(f"{where(case_name, path)} = {shown(value)}: must be a finite number")
    return x


def vector(value, kind, path, case_name, sizes):
    """A field's list of numbers (of one of the lengths ``sizes``), each as ``number`` reads it."""
    if not isinstance(value, (list, tuple)) or len(value) not in sizes:
        want = " or ".join(str(s) for s in sizes)
        raise CaseError(f"{where(case_name, path)} = {shown(value)}: must be a list of {want} quantities")
    return [number(v, kind, f"{path}[{i}]", case_name) for i, v in enumerate(value)]


def check_keys(d, allowed, path, case_name):
    """A table must be a dict; an unknown field (a typo, or a key of another tool) is ignored with
    a CaseWarning naming it, so that a misspelt optional field does not pass silently."""
    if not isinstance(d, dict):
        raise CaseError(f"{where(case_name, path)}: must be a table/object, got {shown(d)}")
    for k in d:
        if k not in allowed:
            warnings.warn(CaseWarning(f"{where(case_name, path + '.' + k if path else k)}: unknown field, ignored "
                                      f"(known: {', '.join(sorted(allowed - {'...'}))})"), stacklevel=2)


def text(d, key, default, path, case_name):
    """``d[key]``, a name: text as the file typed it (a JSON or TOML string), or ``default`` where not given. Any
    other value is refused: written as text it would not be the name the file gave."""
    if key not in d:
        return default
    if not isinstance(d[key], str):
        raise CaseError(f"{where(case_name, path)} = {shown(d[key])}: a name must be text, in double quotes: "
                        f"\"name\": \"...\"")
    return d[key]


def repeated(d, path, case_name):
    """A CaseError naming the first key given more than once in one object of ``d`` (its tables and lists
    walked; ``Table.repeated``), with the values given: JSON's reader keeps the last, TOML's refuses the file."""
    stack = [(d, path)]
    while stack:
        x, at = stack.pop()
        if isinstance(x, dict):
            for k, values in (getattr(x, "repeated", None) or {}).items():
                field = f"{at}.{k}" if at else k
                raise CaseError(f"{where(case_name, field)}: given {len(values)} times in one object ("
                                f"{', '.join(shown(v, 40) for v in values)}); give each field once")
            stack.extend((v, f"{at}.{k}" if at else k) for k, v in reversed(list(x.items())))
        elif isinstance(x, list):
            stack.extend((v, f"{at}[{i}]") for i, v in reversed(list(enumerate(x))))


class Table(dict):
    """A JSON object of a case file (``load``'s ``object_pairs_hook``), with the keys it gave more than once:
    ``repeated``, key -> every value given, in order (None where none was)."""

    repeated = None

    @classmethod
    def of(cls, pairs):
        table = cls(pairs)
        if len(table) < len(pairs):
            given = {}
            for k, v in pairs:
                given.setdefault(k, []).append(v)
            table.repeated = {k: v for k, v in given.items() if len(v) > 1}
        return table


def require(d, key, path, case_name):
    """``d[key]``, or a CaseError naming the missing field."""
    if key not in d:
        raise CaseError(f"{where(case_name, path + '.' + key)}: missing field")
    return d[key]


def positive(x, raw, path, case_name, rule):
    """A CaseError stating ``rule`` unless ``x`` > 0 (``raw``: the value as typed)."""
    if not x > 0:
        raise CaseError(f"{where(case_name, path)} = {raw!r}: {rule}")


class LongInteger(str):
    """An integer literal of a case file too long for any float (more than ``load.MAX_INTEGER_DIGITS`` digits),
    kept as its text so that its case, not the file, is refused (``units.parse_quantity`` names it)."""


def shown(value, most: int = 80) -> str:
    """``value`` as the file wrote it (``units.as_typed``: null, true, a TOML date, else ``repr``), cut to ``most``
    characters with the count of the rest (a value of thousands of digits or a long list would bury the
    message)."""
    text = U.as_typed(value)
    return text if len(text) <= most else f"{text[:most - 20]}... ({len(text)} characters)"


def typed_scale(raw, kind):
    """(SI value of one unit, the unit) of a quantity typed with a unit ("15.95 ft" -> (0.3048, "ft")), or
    None for a bare number, or a unit the same as the SI one shown (``units.SI_DISPLAY``)."""
    unit = U.typed_unit(raw)
    if unit is None or unit == U.SI_DISPLAY[kind][1]:
        return None
    try:
        return U.parse_quantity(f"1 {unit}", kind), unit
    except U.UnitError:
        return None


def given(raw, x, kind) -> str:
    """A value as a message shows it: as typed, and where typed in a unit, in SI too ("'20 ft' (6.096 m)"),
    so that it can be set beside a limit given in SI."""
    scale, label = U.SI_DISPLAY[kind]
    return shown(raw) + (f" ({x / scale:.4g} {label})".rstrip() if typed_scale(raw, kind) else "")


def both(raw, x, kind) -> str:
    """``x`` (SI) in the unit ``raw`` was typed in and in SI ("15.95 ft, 4.862 m"), or in SI alone where
    ``raw`` was a bare number ("4.862 m")."""
    scale, label = U.SI_DISPLAY[kind]
    typed = typed_scale(raw, kind) if raw is not None else None
    as_typed = f"{x / typed[0]:.4g} {typed[1]}, " if typed else ""
    return f"{as_typed}{x / scale:.4g} {label}"


def limit(what, raw, x, kind) -> str:
    """A limit that another input sets, named, in the unit that input was typed in and in SI: "the length
    (15.95 ft, 4.862 m)"; "the length (4.862 m)" where it was a bare number."""
    return f"{what} ({both(raw, x, kind)})"
