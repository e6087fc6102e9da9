"""Case files (JSON or TOML) read into ``Case`` objects (docs/model.md, "Case files"): a file's limits (its size,
nesting, count of cases and integer digits), its text, and its cases, each made by ``build.case_from_dict``.

Errors name the file or the case and raise ``CaseError``. In a file with several cases, a bad case is kept as an
invalid ``Case`` (its ``error`` says why), so that the others are still solved.
"""

from __future__ import annotations

import json
import os
import tomllib
from pathlib import Path

from .build import case_from_dict
from .errors import CaseError
from .fields import LongInteger, Table, shown as _shown
from .inputs import Case

# Limits of a case file (docs/model.md, "Limits"): far beyond any real case file, and within what the program
# can read without running out of memory or stack
MAX_FILE_BYTES = 64 << 20
MAX_DEPTH = 32  # tables and lists inside one another
MAX_CASES = 100_000
MAX_INTEGER_DIGITS = 400  # a longer integer literal is kept as its text: no float holds it


def _json_integer(text):
    return LongInteger(text) if len(text) > MAX_INTEGER_DIGITS else int(text)


def _read(path: Path):
    try:
        with open(path, "rb") as f:  # read at most the limit (a device file such as /dev/zero never ends)
            raw = f.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise CaseError(f"{path}: cannot be read ({err.strerror or err})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise CaseError(f"{path}: larger than {MAX_FILE_BYTES >> 20} MiB, the limit of a case file (docs/model.md, "
                        "\"Limits\"); split it into several files")
    try:
        text = raw.decode("utf-8-sig")  # -sig: a byte-order mark, as some editors write
    except UnicodeDecodeError as err:
        raise CaseError(f"{path}: not a UTF-8 text file (byte {err.start}: {err.reason}); case files are JSON "
                        "or TOML text") from None
    kind = "TOML" if path.suffix.lower() == ".toml" else "JSON"
    if not text.strip():
        raise CaseError(f"{path}: the file is empty; a case file holds one case, or several under \"cases\", as "
                        f"{kind} (docs/model.md, \"Case files\")")
    try:
        data = tomllib.loads(text) if kind == "TOML" else json.loads(text, parse_int=_json_integer,
                                                                       object_pairs_hook=Table.of)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as err:
        other = "" if path.suffix.lower() in (".json", ".toml") else \
            f" (case files are JSON or TOML; a '{path.suffix}' file is read as JSON)"
        raise CaseError(f"{path}: cannot be read as {kind}{other}: {err}") from None
    except RecursionError:
        raise CaseError(f"{path}: lists or tables nested too deep to read (a case file nests at most {MAX_DEPTH} "
                        "deep)") from None
    except ValueError as err:  # TOML: an integer beyond Python's limit of digits
        raise CaseError(f"{path}: cannot be read as {kind}: {_shown(str(err))}") from None
    depth = _depth(data)
    if depth > MAX_DEPTH:
        raise CaseError(f"{path}: lists or tables nested more than {MAX_DEPTH} deep, the limit of a case file "
                        "(docs/model.md, \"Limits\")")
    return data


def _depth(data) -> int:
    """How deep lists and tables nest in ``data`` (a number: 0), counted without recursion."""
    deepest, stack = 0, [(data, 1)]
    while stack:
        x, d = stack.pop()
        if isinstance(x, (dict, list)):
            deepest = max(deepest, d)
            if d <= MAX_DEPTH:  # deeper is refused anyway: no need to walk it all
                stack.extend((v, d + 1) for v in (x.values() if isinstance(x, dict) else x))
    return deepest


def cases_from_data(data, source=None) -> list[Case]:
    """All cases of a loaded file. A file with one case raises CaseError on a bad case; in a
    file with ``cases``, a bad case becomes an invalid Case and the others are kept."""
    if isinstance(data, dict) and "cases" in data:
        for k, values in (getattr(data, "repeated", None) or {}).items():  # a case's own are its case's error
            raise CaseError(f"{source or 'file'}: \"{k}\" given {len(values)} times in the file's object; give it "
                            "once (every case in one list under \"cases\")")
        if not isinstance(data["cases"], list) or not data["cases"]:
            raise CaseError(f"{source or 'file'}: cases must be a non-empty list")
        if len(data["cases"]) > MAX_CASES:
            raise CaseError(f"{source or 'file'}: {len(data['cases'])} cases, more than the {MAX_CASES} of a case "
                            "file (docs/model.md, \"Limits\"); split it, or sweep the inputs that vary")
        out = []
        for i, d in enumerate(data["cases"]):
            given = d.get("name") if isinstance(d, dict) else None
            default = given if isinstance(given, str) else f"case {i + 1}"
            try:
                out.append(case_from_dict(d, f"case {i + 1}", source))
            except CaseError as err:
                out.append(Case(default, None, error=str(err), raw=d if isinstance(d, dict) else {},
                                source=source))
        return out
    return [case_from_dict(data, Path(source).stem if source else "case", source)]


def _checked_path(path, who) -> Path:
    """``path`` as a Path to a file that is there, refused unless it is a path (a str or an os.PathLike: a case
    given as a dict is read by ``case_from_dict``, not here), names a file that exists and not a directory."""
    if not isinstance(path, (str, os.PathLike)):
        read = (": a case given as a dict is read by ks_jax.case.case_from_dict (a dict of \"cases\" by "
                "ks_jax.case.cases_from_data)") if isinstance(path, dict) else ""
        raise TypeError(f"{who} takes the path of a case file (a str or a pathlib.Path), got a "
                        f"{type(path).__name__}{read}")
    path = Path(path)
    if not path.exists():
        raise CaseError(f"{path}: no such file")
    if path.is_dir():
        raise CaseError(f"{path}: is a directory; give a case file (JSON or TOML)")
    return path


def load_cases(path) -> list[Case]:
    """Every case in a JSON or TOML file (see ``cases_from_data``)."""
    path = _checked_path(path, "load_cases")
    return cases_from_data(_read(path), str(path))


def load_case(path):
    """The case in a file: a ``Case`` if the file holds one, a list of Case if it holds ``cases`` (the file read
    once)."""
    path = _checked_path(path, "load_case")
    data = _read(path)
    cases = cases_from_data(data, str(path))
    return cases if isinstance(data, dict) and "cases" in data else cases[0]
