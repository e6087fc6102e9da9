"""Case files <-> pytrees (MODEL.md sections 2 and 6). Units exist only here and in reports.

A case is read into ``CaseInputs``: one pytree of SI arrays (angles in rad, rates in rad/s)
that holds every scalar a user may vary, sweep or fit. ``to_pytrees`` turns it into the
kernel's (Vehicle, State, Vehicle, State, Contact); ``input_path``/``set_input`` and
``output_path`` address single numbers by the paths of MODEL.md ("vehicles[1].speed",
"contact.point[0]", "vehicles[0].delta_v_body[0]").

Errors name the case, the field path, the value and the rule, and raise ``CaseError``.
In a file with several cases, a bad case is kept as an invalid ``Case`` (its ``error`` says
why) so that the others are still solved.
"""

from __future__ import annotations

import functools
import json
import math
import operator
import warnings
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import linalg as la
from . import units as U
from .types import INVALID_NONFINITE, INVALID_SPEED_1, INVALID_SPEED_2, NO_CONTACT, OK, Contact, State, Vehicle
from .types import normal_from_angles


class CaseError(ValueError):
    """A user error in a case file or case dict; the message is meant for the user."""


class VehicleInputs(NamedTuple):
    """One vehicle's inputs, SI. inertia is always (3, 3) (body frame); velocity is held as
    horizontal ``speed``, ``course`` and ``velocity_z``; angular_velocity (3,) rad/s, global."""

    mass: Any
    inertia: Any
    length: Any
    width: Any
    height: Any
    cg_to_front: Any
    cg_height: Any
    position: Any
    yaw: Any
    pitch: Any
    roll: Any
    speed: Any
    course: Any
    velocity_z: Any
    angular_velocity: Any


class ContactInputs(NamedTuple):
    """point (3,) m; normal: azimuth (rad); normal_pitch (rad); restitution; friction;
    penetration_time (s). point/normal are placeholders (zeros) under automatic contact."""

    point: Any
    normal: Any
    normal_pitch: Any
    restitution: Any
    friction: Any
    penetration_time: Any


class CaseInputs(NamedTuple):
    vehicles: tuple
    contact: ContactInputs


@dataclass(frozen=True)
class Case:
    """One case: its name, its inputs (None if invalid), and which contact parts are automatic."""

    name: str
    inputs: CaseInputs | None
    auto_point: bool = False
    auto_normal: bool = False
    vehicle_names: tuple = ("vehicle 1", "vehicle 2")
    error: str | None = None
    raw: dict = field(default_factory=dict, compare=False, repr=False)
    source: str | None = None

    @property
    def valid(self) -> bool:
        return self.error is None


# ---------------------------------------------------------------------------------------
# what each field is

VEHICLE_FIELDS = {  # key -> (kind, shape); shape None = scalar
    "mass": ("mass", None),
    "weight": ("force", None),
    "inertia": ("inertia", "inertia"),
    "length": ("length", None),
    "width": ("length", None),
    "height": ("length", None),
    "cg_to_front": ("length", None),
    "cg_height": ("length", None),
    "position": ("length", "vec23"),
    "yaw": ("angle", None),
    "pitch": ("angle", None),
    "roll": ("angle", None),
    "velocity": ("velocity", "vec23"),
    "speed": ("velocity", None),
    "course": ("angle", None),
    "yaw_rate": ("angular_velocity", None),
    "angular_velocity": ("angular_velocity", "vec3"),
}
CONTACT_FIELDS = {
    "point": ("length", "vec3"),
    "normal": ("angle", "normal"),
    "normal_pitch": ("angle", None),
    "restitution": ("dimensionless", None),
    "friction": ("dimensionless", None),
    "penetration_time": ("time", None),
}
TEXT_FIELDS = {"name", "description", "notes", "source", "...", "make", "model"}
CASE_FIELDS = {"name", "description", "notes", "source", "vehicles", "contact", "unknowns", "evidence", "options",
               "reference"}

# kind of every scalar input path's leaf (for unit strings in sweeps and fits)
INPUT_KINDS = {
    "mass": "mass", "inertia": "inertia", "length": "length", "width": "length", "height": "length",
    "cg_to_front": "length", "cg_height": "length", "position": "length", "yaw": "angle", "pitch": "angle",
    "roll": "angle", "speed": "velocity", "course": "angle", "velocity_z": "velocity",
    "angular_velocity": "angular_velocity", "yaw_rate": "angular_velocity",
    "point": "length", "normal": "angle", "normal_pitch": "angle", "restitution": "dimensionless",
    "friction": "dimensionless", "penetration_time": "time",
}
# kind of every output field (section 4); "degrees" = reported in degrees
OUTPUT_KINDS = {
    "point": "length", "normal": "dimensionless", "time": "time", "impulse": "impulse",
    "impulse_magnitude": "impulse", "impulse_normal": "impulse", "impulse_tangential": "impulse",
    "impulse_azimuth": "degrees", "impulse_elevation": "degrees", "sliding": "dimensionless",
    "closing_velocity": "velocity", "separation_velocity": "velocity", "energy_loss": "energy",
    "delta_v": "velocity", "delta_v_magnitude": "velocity", "delta_v_body": "velocity",
    "delta_yaw_rate": "angular_velocity", "velocity_after": "velocity", "speed_after": "velocity",
    "course_after": "degrees", "angular_velocity_after": "angular_velocity",
    "yaw_rate_after": "angular_velocity", "pdof": "degrees", "pdof_clock": "dimensionless",
    "crush": "length", "ees": "velocity",
}


def _where(case_name, path):
    return f"case '{case_name}': {path}"


def _number(value, kind, path, case_name):
    try:
        x = U.parse_quantity(value, kind)
    except U.UnitError as err:
        raise CaseError(f"{_where(case_name, path)} = {value!r}: {err}") from None
    if not math.isfinite(x):
        raise CaseError(f"{_where(case_name, path)} = {value!r}: must be a finite number")
    return x


def _vector(value, kind, path, case_name, sizes):
    if not isinstance(value, (list, tuple)) or len(value) not in sizes:
        want = " or ".join(str(s) for s in sizes)
        raise CaseError(f"{_where(case_name, path)} = {value!r}: must be a list of {want} quantities")
    return [_number(v, kind, f"{path}[{i}]", case_name) for i, v in enumerate(value)]


def _inertia(value, path, case_name):
    if isinstance(value, (list, tuple)) and len(value) == 3 and all(isinstance(r, (list, tuple)) for r in value):
        m = np.array([_vector(r, "inertia", f"{path}[{i}]", case_name, (3,)) for i, r in enumerate(value)])
        if not np.allclose(m, m.T, rtol=1e-9, atol=0):
            raise CaseError(f"{_where(case_name, path)} = {value!r}: an inertia tensor must be symmetric")
        if np.any(np.linalg.eigvalsh(m) <= 0):
            raise CaseError(f"{_where(case_name, path)} = {value!r}: an inertia tensor must be positive definite")
        return m
    moments = _vector(value, "inertia", path, case_name, (3,))
    for i, x in enumerate(moments):
        if x <= 0:
            raise CaseError(f"{_where(case_name, path)}[{i}] = {value[i]!r}: principal moments of inertia must be positive")
    return np.diag(moments)


class CaseWarning(UserWarning):
    """Something in a case that is ignored (an unknown field) or that costs precision; it is still solved."""


FAR_IN_FLOAT32 = 1e3  # m: a scene this far from the origin loses precision in float32 (crush, EES)


def _computes_in_float32(dtype=None) -> bool:
    return jnp.dtype(dtype or jnp.result_type(float)) == jnp.float32


def _xy(x):
    return np.asarray(x, np.float64)[..., :2]


def scene_origin(inputs: CaseInputs, extra=(), dtype=None):
    """Where ``solve`` and ``sweep`` move the origin before computing: None where JAX computes in float64,
    or where no CG or impulse centroid lies more than FAR_IN_FLOAT32 from the origin; else the CGs'
    midpoint (x, y), float64, shape (..., 2) (0 for rows of a batch that are near the origin).

    Float32 (JAX's default) keeps about 7 digits: at survey coordinates (5e5 m) a position keeps ~3 cm,
    and crush and EES come out 30% off. The exchange is the same in a translated scene (MODEL.md
    section 3), so the scene is moved on the host in float64 (``move_scene``) and ``contact.point`` moved
    back (``origin_offset``). ``extra``: more x, y values that the scene reaches (a sweep's positions).
    dtype: the compute dtype (default: JAX's default float)."""
    if not _computes_in_float32(dtype):
        return None
    cg = [_xy(v.position) for v in inputs.vehicles]
    reach = np.maximum(np.abs(cg[0]).max(-1), np.abs(cg[1]).max(-1))
    reach = np.maximum(reach, np.abs(_xy(inputs.contact.point)).max(-1))
    reach = np.maximum(reach, max((np.abs(np.asarray(e, np.float64)).max() for e in extra), default=0.0))
    far = reach > FAR_IN_FLOAT32
    if not far.any():
        return None
    return np.where(far[..., None], (cg[0] + cg[1]) / 2, 0.0)


def move_scene(inputs: CaseInputs, origin, auto_point=False) -> CaseInputs:
    """``inputs`` with the CG positions and the impulse centroid given about ``origin`` (x, y; float64,
    on the host): the same scene, translated (``scene_origin``). auto_point: the centroid is automatic
    (its input a placeholder, left as it is)."""
    def moved(x):
        x = np.array(x, np.float64)
        x[..., :2] -= origin
        return x

    point = inputs.contact.point if auto_point else moved(inputs.contact.point)
    return inputs._replace(vehicles=tuple(v._replace(position=moved(v.position)) for v in inputs.vehicles),
                           contact=inputs.contact._replace(point=point))


def xy_index(path: str):
    """0 or 1 where ``path`` is the x or y of a CG position or of the impulse centroid (an input, or
    the output contact.point[k]), else None."""
    _, _, name, idx = parse_path(path)
    return idx[0] if name in ("position", "point") and idx[:1] in ((0,), (1,)) else None


def origin_offset(path: str, origin):
    """What ``move_scene`` subtracted from the input or output at ``path`` ("vehicles[0].position[0]",
    "contact.point[1]"): origin[..., k] for an x or y position or centroid, else None."""
    k = xy_index(path)
    return None if origin is None or k is None else origin[..., k]


def warn_far_from_origin(inputs: CaseInputs, extra=(), what="the scene", about="the origin", auto_point=False):
    """Warn (CaseWarning) where JAX computes in float32 (its default) and a CG, the impulse centroid (unless
    ``auto_point``) or an ``extra`` x, y value (a sweep's positions) lies more than FAR_IN_FLOAT32 from
    ``about`` even after ``move_scene``: vehicles kilometres apart, or a sweep of positions over kilometres."""
    if not _computes_in_float32():
        return
    xy = [np.abs(_xy(v.position)).max() for v in inputs.vehicles]
    if not auto_point:
        xy.append(np.abs(_xy(inputs.contact.point)).max())
    xy += [np.abs(np.asarray(e, np.float64)).max() for e in extra]
    far = max(xy)
    if far > FAR_IN_FLOAT32:
        warnings.warn(f"{what} reaches {far:.3g} m from {about} and JAX computes in float32 (its default): about 7 "
                      f"digits, so positions lose up to {far * 6e-8:.2g} m and crush and EES lose precision (0.5% "
                      "at 10 km). Enable float64 (jax.config.update('jax_enable_x64', True), as ks-jax's command "
                      "line does)", CaseWarning, stacklevel=3)


def _check_keys(d, allowed, path, case_name):
    """A table must be a dict; an unknown field (a typo, or a key of another tool) is ignored with
    a CaseWarning naming it, so that a misspelt optional field does not pass silently."""
    if not isinstance(d, dict):
        raise CaseError(f"{_where(case_name, path)}: must be a table/object, got {d!r}")
    for k in d:
        if k not in allowed:
            warnings.warn(CaseWarning(f"{_where(case_name, path + '.' + k if path else k)}: unknown field, ignored "
                                      f"(known: {', '.join(sorted(allowed - {'...'}))})"), stacklevel=2)


def _require(d, key, path, case_name):
    if key not in d:
        raise CaseError(f"{_where(case_name, path + '.' + key)}: missing field")
    return d[key]


def _positive(x, raw, path, case_name, rule):
    if not x > 0:
        raise CaseError(f"{_where(case_name, path)} = {raw!r}: {rule}")


def _vehicle_inputs(d, i, case_name):
    path = f"vehicles[{i}]"
    _check_keys(d, set(VEHICLE_FIELDS) | TEXT_FIELDS, path, case_name)
    num = lambda k: _number(d[k], VEHICLE_FIELDS[k][0], f"{path}.{k}", case_name)  # noqa: E731
    if "mass" in d and "weight" in d:
        raise CaseError(f"{_where(case_name, path)}: give mass or weight, not both")
    if "mass" in d:
        mass = num("mass")
        _positive(mass, d["mass"], f"{path}.mass", case_name, "mass must be positive")
    elif "weight" in d:
        mass = num("weight") / U.G0
        _positive(mass, d["weight"], f"{path}.weight", case_name, "weight must be positive")
    else:
        raise CaseError(f"{_where(case_name, path + '.mass')}: missing field (give mass or weight)")
    inertia = _inertia(_require(d, "inertia", path, case_name), f"{path}.inertia", case_name)
    dims = {}
    for k in ("length", "width", "height", "cg_to_front", "cg_height"):
        _require(d, k, path, case_name)
        dims[k] = num(k)
    for k in ("length", "width", "height"):
        _positive(dims[k], d[k], f"{path}.{k}", case_name, f"{k} must be positive")
    if not 0 <= dims["cg_to_front"] <= dims["length"]:
        raise CaseError(f"{_where(case_name, path + '.cg_to_front')} = {d['cg_to_front']!r}: "
                        f"must be between 0 and the length ({dims['length']:.4g} m)")
    if not 0 <= dims["cg_height"] <= dims["height"]:
        raise CaseError(f"{_where(case_name, path + '.cg_height')} = {d['cg_height']!r}: "
                        f"must be between 0 and the height ({dims['height']:.4g} m)")
    pos = _vector(_require(d, "position", path, case_name), "length", f"{path}.position", case_name, (2, 3))
    if len(pos) == 2:
        pos.append(dims["cg_height"])
    yaw = num("yaw") if "yaw" in d else None
    if yaw is None:
        raise CaseError(f"{_where(case_name, path + '.yaw')}: missing field")
    pitch = num("pitch") if "pitch" in d else 0.0
    roll = num("roll") if "roll" in d else 0.0
    if "velocity" in d and ("speed" in d or "course" in d):
        raise CaseError(f"{_where(case_name, path)}: give velocity, or speed (and course), not both")
    if "velocity" in d:
        vel = _vector(d["velocity"], "velocity", f"{path}.velocity", case_name, (2, 3))
        speed, course = math.hypot(vel[0], vel[1]), math.atan2(vel[1], vel[0])
        vz = vel[2] if len(vel) == 3 else 0.0
    elif "speed" in d:
        speed = num("speed")
        if speed < 0:
            raise CaseError(f"{_where(case_name, path + '.speed')} = {d['speed']!r}: speed must be >= 0 "
                            "(reverse the course for backwards travel)")
        course = num("course") if "course" in d else yaw
        vz = 0.0
    else:
        raise CaseError(f"{_where(case_name, path + '.speed')}: missing field (give speed or velocity)")
    if "yaw_rate" in d and "angular_velocity" in d:
        raise CaseError(f"{_where(case_name, path)}: give yaw_rate or angular_velocity, not both")
    if "angular_velocity" in d:
        w = _vector(d["angular_velocity"], "angular_velocity", f"{path}.angular_velocity", case_name, (3,))
    else:
        w = [0.0, 0.0, num("yaw_rate") if "yaw_rate" in d else 0.0]
    return VehicleInputs(mass, inertia, dims["length"], dims["width"], dims["height"], dims["cg_to_front"],
                         dims["cg_height"], np.array(pos), yaw, pitch, roll, speed, course, vz, np.array(w))


def _contact_inputs(d, case_name):
    path = "contact"
    _check_keys(d, set(CONTACT_FIELDS) | TEXT_FIELDS, path, case_name)
    num = lambda k: _number(d[k], CONTACT_FIELDS[k][0], f"contact.{k}", case_name)  # noqa: E731
    _require(d, "restitution", path, case_name)
    eps = num("restitution")
    if not -1 <= eps <= 1:
        raise CaseError(f"{_where(case_name, 'contact.restitution')} = {d['restitution']!r}: "
                        "restitution must be in [-1, 1]")
    _require(d, "friction", path, case_name)
    mu = num("friction")
    if mu < 0:
        raise CaseError(f"{_where(case_name, 'contact.friction')} = {d['friction']!r}: friction must be >= 0")
    pt = num("penetration_time") if "penetration_time" in d else 0.0
    if pt < 0:
        raise CaseError(f"{_where(case_name, 'contact.penetration_time')} = {d['penetration_time']!r}: "
                        "penetration_time must be >= 0")
    normal_pitch = num("normal_pitch") if "normal_pitch" in d else 0.0
    auto_point = "point" not in d
    point = np.zeros(3) if auto_point else np.array(_vector(d["point"], "length", "contact.point", case_name, (3,)))
    auto_normal = "normal" not in d
    azimuth = 0.0
    if not auto_normal:
        raw = d["normal"]
        if isinstance(raw, (list, tuple)):
            vec = _vector(raw, "dimensionless", "contact.normal", case_name, (2, 3))
            vec = vec + [0.0] * (3 - len(vec))
            if math.hypot(*vec) == 0:
                raise CaseError(f"{_where(case_name, 'contact.normal')} = {raw!r}: the normal must be a non-zero vector")
            azimuth = math.atan2(vec[1], vec[0])
            if "normal_pitch" in d:
                raise CaseError(f"{_where(case_name, 'contact.normal_pitch')}: give the pitch in the vector "
                                "or use an azimuth for contact.normal, not both")
            normal_pitch = math.atan2(vec[2], math.hypot(vec[0], vec[1]))
        else:
            azimuth = num("normal")
    return ContactInputs(point, azimuth, normal_pitch, eps, mu, pt), auto_point, auto_normal


def case_from_dict(d: dict, default_name: str = "case", source: str | None = None) -> Case:
    """Read one case (a dict as in a JSON/TOML file). Raises CaseError."""
    if not isinstance(d, dict):
        raise CaseError(f"case '{default_name}': a case must be an object/table, got {type(d).__name__}")
    name = str(d.get("name", default_name))
    _check_keys(d, CASE_FIELDS, "", name)
    vehicles = _require(d, "vehicles", "", name) if "vehicles" in d else None
    if vehicles is None:
        raise CaseError(f"case '{name}': vehicles: missing field")
    if not isinstance(vehicles, list) or len(vehicles) != 2:
        n = len(vehicles) if isinstance(vehicles, list) else vehicles
        raise CaseError(f"case '{name}': vehicles = {n!r} vehicles: a case needs exactly two vehicles")
    if "contact" not in d:
        raise CaseError(f"case '{name}': contact: missing field")
    veh = tuple(_vehicle_inputs(v, i, name) for i, v in enumerate(vehicles))
    contact, auto_point, auto_normal = _contact_inputs(d["contact"], name)
    if "reference" in d:
        _check_reference(d["reference"], name)
    inputs = CaseInputs(veh, contact)
    names = tuple(str(v.get("name", f"vehicle {i + 1}")) for i, v in enumerate(vehicles))
    return Case(name, inputs, auto_point, auto_normal, names, None, d, source)


def _check_reference(reference, case_name):
    """``reference``: reported results to print beside ks-jax's (an output path -> its value, e.g. the
    manual's panel); checked when the case is read, so that a bad entry costs its case only."""
    if not isinstance(reference, dict):
        raise CaseError(f"{_where(case_name, 'reference')} = {reference!r}: must map output paths to reported "
                        "values, e.g. {\"contact.impulse_magnitude\": \"1336.904 lbf*s\"}")
    for path, value in reference.items():
        try:
            check_output_path(path)
        except CaseError as err:
            raise CaseError(f"{_where(case_name, 'reference')}: {err}") from None
        parse_output_value(value, path, case_name, f"reference.{path}")


def _read(path: Path):
    try:
        text = path.read_bytes().decode("utf-8-sig")  # -sig: a byte-order mark, as some editors write
    except UnicodeDecodeError as err:
        raise CaseError(f"{path}: not a UTF-8 text file (byte {err.start}: {err.reason}); case files are JSON "
                        "or TOML text") from None
    try:
        if path.suffix.lower() == ".toml":
            return tomllib.loads(text)
        return json.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as err:
        kind = "TOML" if path.suffix.lower() == ".toml" else "JSON"
        other = "" if path.suffix.lower() in (".json", ".toml") else \
            f" (case files are JSON or TOML; a '{path.suffix}' file is read as JSON)"
        raise CaseError(f"{path}: cannot be read as {kind}{other}: {err}") from None


def cases_from_data(data, source=None) -> list[Case]:
    """All cases of a loaded file. A file with one case raises CaseError on a bad case; in a
    file with ``cases``, a bad case becomes an invalid Case and the others are kept."""
    if isinstance(data, dict) and "cases" in data:
        if not isinstance(data["cases"], list) or not data["cases"]:
            raise CaseError(f"{source or 'file'}: cases must be a non-empty list")
        out = []
        for i, d in enumerate(data["cases"]):
            default = d.get("name", f"case {i + 1}") if isinstance(d, dict) else f"case {i + 1}"
            try:
                out.append(case_from_dict(d, f"case {i + 1}", source))
            except CaseError as err:
                out.append(Case(str(default), None, error=str(err), raw=d if isinstance(d, dict) else {},
                                source=source))
        return out
    return [case_from_dict(data, Path(source).stem if source else "case", source)]


def load_cases(path) -> list[Case]:
    """Every case in a JSON or TOML file (see ``cases_from_data``)."""
    path = Path(path)
    if not path.exists():
        raise CaseError(f"{path}: no such file")
    if path.is_dir():
        raise CaseError(f"{path}: is a directory; give a case file (JSON or TOML)")
    return cases_from_data(_read(path), str(path))


def load_case(path):
    """The case in a file: a ``Case`` if the file holds one, a list of Case if it holds ``cases``."""
    cases = load_cases(path)
    data = _read(Path(path))
    return cases if isinstance(data, dict) and "cases" in data else cases[0]


# ---------------------------------------------------------------------------------------
# inputs -> kernel pytrees


def as_arrays(inputs: CaseInputs, dtype=None) -> CaseInputs:
    """Every leaf as a jnp array (of ``dtype``, default: JAX's default float)."""
    import jax

    dtype = dtype or jnp.result_type(float)
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=dtype), inputs)


def to_pytrees(inputs: CaseInputs):
    """(Vehicle, State, Vehicle, State, Contact) from CaseInputs. Pure and differentiable.

    A velocity or normal made from a non-finite speed, course, velocity_z or angle is NaN, so that
    the exchange gives the row its status; it is computed from stand-ins (the double-where), so that
    the row's zero cotangent times an infinite derivative cannot make NaN the gradient of a parameter
    it shares with other rows."""
    out = []
    for v in inputs.vehicles:
        vehicle = Vehicle(v.mass, v.inertia, v.length, v.width, v.height, v.cg_to_front, v.cg_height)
        ok, (speed, course, vz) = _finite_stand_ins(v.speed, v.course, v.velocity_z)
        sin, cos = la.sincos(course)
        velocity = jnp.where(ok, jnp.stack([speed * cos, speed * sin, vz * jnp.ones_like(speed)]), jnp.nan)
        state = State(v.position, velocity, v.yaw, v.pitch, v.roll, v.angular_velocity)
        out += [vehicle, state]
    c = inputs.contact
    ok, (azimuth, pitch) = _finite_stand_ins(c.normal, c.normal_pitch)
    contact = Contact(c.point, jnp.where(ok, normal_from_angles(azimuth, pitch), jnp.nan), c.restitution,
                      c.friction, c.penetration_time)
    return (*out, contact)


def _finite_stand_ins(*xs):
    """(ok, xs with 0 for each where ok is False): ok where all of ``xs`` are finite."""
    ok = functools.reduce(operator.and_, [jnp.isfinite(x) for x in xs])
    return ok, tuple(jnp.where(ok, x, jnp.zeros_like(x)) for x in xs)


# ---------------------------------------------------------------------------------------
# paths

_PATH = re.compile(r"^(vehicles)\[(\d+)\]\.(\w+)((?:\[\d+\])*)$|^(contact)\.(\w+)((?:\[\d+\])*)$")


class PathError(CaseError):
    pass


def canonical_path(path: str) -> str:
    """``path`` as ``parse_path`` reads it, without spaces: "vehicles[0]. yaw" is "vehicles[0].yaw"."""
    return path.strip().replace(" ", "")


def parse_path(path: str):
    """'vehicles[1].speed' -> ('vehicles', 1, 'speed', ()); 'contact.point[0]' -> ('contact', None, 'point', (0,))."""
    m = _PATH.match(canonical_path(path))
    if not m:
        raise PathError(f"path '{path}': not of the form vehicles[i].field[k] or contact.field[k]")
    if m.group(1):
        idx = tuple(int(k) for k in re.findall(r"\d+", m.group(4)))
        vi = int(m.group(2))
        if vi not in (0, 1):
            raise PathError(f"path '{path}': vehicle index must be 0 or 1")
        return "vehicles", vi, m.group(3), idx
    idx = tuple(int(k) for k in re.findall(r"\d+", m.group(7)))
    return "contact", None, m.group(6), idx


def _input_leaf(path):
    """(group, vehicle index, field in CaseInputs, index tuple) for an input path."""
    group, vi, name, idx = parse_path(path)
    if group == "vehicles":
        if name == "yaw_rate" and not idx:
            return group, vi, "angular_velocity", (2,)
        if name == "inertia" and len(idx) == 1:
            if idx[0] > 2:
                raise PathError(f"path '{path}': index out of range (0..2)")
            return group, vi, "inertia", (idx[0], idx[0])
        if name not in VehicleInputs._fields:
            hint = {"velocity": " (vary speed and course instead)",
                    "weight": f" (a case's weight sets its mass: use vehicles[{vi}].mass, in lb where weights "
                              "are in lbf)"}.get(name, "")
            raise PathError(f"path '{path}': '{name}' is not a vehicle input{hint}; "
                            f"inputs are {', '.join(VehicleInputs._fields)}, yaw_rate")
    elif name not in ContactInputs._fields:
        raise PathError(f"path '{path}': '{name}' is not a contact input; inputs are {', '.join(ContactInputs._fields)}")
    shapes = {"position": 1, "angular_velocity": 1, "point": 1, "inertia": 2}
    if len(idx) != shapes.get(name, 0):
        need = shapes.get(name, 0)
        raise PathError(f"path '{path}': '{name}' needs {need} index{'es' if need != 1 else ''} to name a number")
    if any(k > 2 for k in idx):
        raise PathError(f"path '{path}': index out of range (0..2)")
    return group, vi, name, idx


def input_kind(path) -> str:
    """The unit kind of an input path (see ``units.SI_UNITS``); PathError for an unknown path."""
    group, vi, name, idx = parse_path(path)
    _input_leaf(path)
    return INPUT_KINDS[name]


def get_input(inputs: CaseInputs, path: str):
    """The value of the input ``path`` (section 6: "vehicles[1].speed", "contact.point[0]",
    "vehicles[0].yaw_rate", ...) in ``inputs`` (a case's ``inputs``), SI (angles in rad); a PathError
    names a path that is not an input. ``set_input`` is its converse."""
    group, vi, name, idx = _input_leaf(path)
    leaf = getattr(inputs.vehicles[vi] if group == "vehicles" else inputs.contact, name)
    return jnp.asarray(leaf)[idx] if idx else leaf


def set_input(inputs: CaseInputs, path: str, value) -> CaseInputs:
    """A copy of ``inputs`` with the number at ``path`` replaced by ``value`` (SI; traceable). A
    product of inertia (``inertia[i][j]``, i != j) sets [j][i] too: the tensor stays symmetric."""
    group, vi, name, idx = _input_leaf(path)
    try:
        dtype = None if value is None else jnp.result_type(value)
    except TypeError:
        dtype = None
    if dtype is None or not jnp.issubdtype(dtype, jnp.number) or jnp.shape(value) != ():
        raise CaseError(f"set_input '{path}' = {value!r}: the value must be one number, in SI units (for a "
                        "unit string, convert it first: ks_jax.units.parse_quantity)")
    holder = inputs.vehicles[vi] if group == "vehicles" else inputs.contact
    leaf = getattr(holder, name)
    new = jnp.asarray(leaf).at[idx].set(value) if idx else value
    if name == "inertia" and len(idx) == 2 and idx[0] != idx[1]:
        new = new.at[idx[::-1]].set(value)
    holder = holder._replace(**{name: new})
    if group == "vehicles":
        vehicles = tuple(holder if i == vi else v for i, v in enumerate(inputs.vehicles))
        return inputs._replace(vehicles=vehicles)
    return inputs._replace(contact=holder)


def speed_status(inputs: CaseInputs, status):
    """``status`` (() int, the exchange's) with INVALID_SPEED_1 (2) where vehicle 1's (2's) ``speed``
    is negative and ``status`` is not already invalid (the exchange's reasons come first).

    A case file refuses a negative speed; a swept, sampled or fitted one can reach it, and
    ``to_pytrees`` would turn it into travel backwards along the course. ``solve_inputs`` and the
    sweeps give such a row this status and NaN results instead (traceable, per row)."""
    s1, s2 = inputs.vehicles[0].speed, inputs.vehicles[1].speed
    code = jnp.where(s1 < 0, INVALID_SPEED_1, jnp.where(s2 < 0, INVALID_SPEED_2, OK))
    return jnp.where((code != OK) & (status < INVALID_NONFINITE), code, status).astype(jnp.asarray(status).dtype)


# a typical size in SI of each kind of input that can make the results overflow (angles, restitution and
# penetration_time cannot): what "out of scale" is measured against in ``farthest_out_of_scale``
TYPICAL_SIZE = {"mass": 1500.0, "inertia": 2000.0, "length": 4.0, "velocity": 20.0, "angular_velocity": 1.0,
                "dimensionless": 1.0}


def farthest_out_of_scale(inputs: CaseInputs) -> str:
    """The input whose size is farthest from its kind's ``TYPICAL_SIZE`` (by the ratio, larger or smaller),
    as "vehicles[0].speed = 4.4704e+199 m/s": the one to name where a row's results overflow (status
    INVALID_OVERFLOW: the inputs are finite, the results are not). Zeros are left out."""
    worst, text = -1.0, ""
    for group, vi, holder in [("vehicles", i, v) for i, v in enumerate(inputs.vehicles)] + \
            [("contact", None, inputs.contact)]:
        for name, value in holder._asdict().items():
            kind = INPUT_KINDS.get(name)
            if kind not in TYPICAL_SIZE or name == "restitution":
                continue
            a = np.asarray(value, dtype=np.float64)
            size = np.abs(a)
            with np.errstate(divide="ignore"):
                far = np.where((size > 0) & np.isfinite(size), np.abs(np.log10(size / TYPICAL_SIZE[kind])), -1.0)
            k = np.unravel_index(int(np.argmax(far)), far.shape) if far.ndim else ()
            if far[k] > worst:
                where = f"vehicles[{vi}].{name}" if group == "vehicles" else f"contact.{name}"
                unit = U.SI_UNITS[kind]
                worst, text = float(far[k]), f"{where}{''.join(f'[{j}]' for j in k)} = {a[k]:.5g}" + \
                    (f" {unit}" if unit else "")
    return text


def automatic_part(case: "Case", path) -> str | None:
    """"point" or "normal" if ``path`` names the part of the contact that automatic contact computes
    in ``case`` (not an input there: a sweep or a fit refuses to vary it), else None."""
    _, _, name, _ = _input_leaf(path)
    return name if (name == "point" and case.auto_point or name == "normal" and case.auto_normal) else None


def input_ties(case: "Case", paths) -> tuple:
    """((k, path), ...): the inputs that follow ``paths[k]`` when the inputs at ``paths`` are varied (a
    sweep, a fit), as re-solving the case file with the new value would move them (MODEL.md section 2):
    - a vehicle's course defaults to its yaw: where the case gives neither ``course`` nor ``velocity``
      for vehicle i, its course is still its yaw (not changed since, e.g. by ``set_input``) and
      ``vehicles[i].course`` is not among ``paths``, turning the vehicle turns its travel too;
    - a CG's height z defaults to ``cg_height``: where the case gives vehicle i a 2-D position, its z
      is still its ``cg_height`` and neither ``vehicles[i].position[2]`` nor ``vehicles[i].position`` is
      among ``paths``, a new ``cg_height`` moves the CG to it.
    So a sweep or fit at the case's own values solves the case as it is."""
    paths = [canonical_path(p) for p in paths]
    ties = []
    vehicles = case.raw.get("vehicles") if isinstance(case.raw, dict) else None
    for k, path in enumerate(paths):
        group, vi, name, _ = parse_path(path)
        if group != "vehicles" or name not in ("yaw", "cg_height"):
            continue
        raw = vehicles[vi] if isinstance(vehicles, list) and vi < len(vehicles) else {}
        raw = raw if isinstance(raw, dict) else {}
        v = case.inputs.vehicles[vi]
        if name == "yaw" and "course" not in raw and "velocity" not in raw and f"vehicles[{vi}].course" not in paths \
                and np.array_equal(np.asarray(v.course), np.asarray(v.yaw)):
            ties.append((k, f"vehicles[{vi}].course"))
        position = raw.get("position")
        if name == "cg_height" and isinstance(position, list) and len(position) == 2 \
                and not {f"vehicles[{vi}].position[2]", f"vehicles[{vi}].position"} & set(paths) \
                and np.array_equal(np.asarray(v.position)[..., 2], np.asarray(v.cg_height)):
            ties.append((k, f"vehicles[{vi}].position[2]"))
    return tuple(ties)


def check_output_path(path: str):
    """Raise PathError unless ``path`` names a number among the section 4 results."""
    from .types import ContactResult, VehicleResult

    group, vi, name, idx = parse_path(path)
    fields = VehicleResult._fields if group == "vehicles" else ContactResult._fields
    if group == "contact" and name == "status":
        raise PathError(f"path '{path}': the status is a code, not a number to sweep, fit or compare: read "
                        "result.contact.status (ks_jax.status_text gives its words); a sweep always returns "
                        "'status'")
    if name not in fields or name == "status":
        raise PathError(f"path '{path}': '{name}' is not a {'vehicle' if group == 'vehicles' else 'contact'} result; "
                        f"results are {', '.join(f for f in fields if f != 'status')}")
    vector = name in {"point", "normal", "impulse", "closing_velocity", "separation_velocity", "delta_v",
                      "delta_v_body", "velocity_after", "angular_velocity_after"}
    if vector and (len(idx) != 1 or idx[0] > 2):
        raise PathError(f"path '{path}': '{name}' is a vector: name a component, e.g. {name}[0]"
                        if len(idx) != 1 else f"path '{path}': index out of range (0..2)")
    if not vector and idx:
        raise PathError(f"path '{path}': '{name}' is a number and takes no index")
    return group, vi, name, idx


def get_output(result, path: str):
    """The number at an output path of a (possibly batched) ExchangeResult."""
    group, vi, name, idx = check_output_path(path)
    leaf = getattr(result.vehicles[vi] if group == "vehicles" else result.contact, name)
    return leaf[(..., *idx)] if idx else leaf


# results that are directions in degrees, compared on the circle (359 and 1 are 2 degrees apart)
CIRCULAR_OUTPUTS = frozenset({"pdof", "impulse_azimuth", "course_after"})
# results that MODEL.md section 4 leaves undefined in some solved rows, and why
_IMPULSE_DIRECTIONS = ("pdof", "pdof_clock", "impulse_azimuth", "impulse_elevation")
_CONTACT_ONLY = ("time", "point", "normal", "closing_velocity", "separation_velocity")  # contact.*
UNDEFINED_REASONS = {
    "direction": "no impulse was exchanged (separating, no contact, restitution -1): it has no direction",
    "contact": "the vehicles never touch within the search horizon: there is no first contact, centroid, "
               "normal or relative velocity at one",
    "ees": "both crushes are 0 (the centroid lies inside neither box, or the vehicles never touch) or the "
           "energy loss is negative",
    "heading": "the vehicle is at rest after the exchange: it has no direction of travel",
}
REST_RATIO = 1e-6  # a horizontal speed after below this fraction of (speed before + delta-V) is rounding: at rest


def undefined_kind(path: str) -> str | None:
    """Which ``UNDEFINED_REASONS`` can leave the result at ``path`` undefined in a solved row; None: never."""
    group, _, name, _ = parse_path(path)
    if name in _IMPULSE_DIRECTIONS:
        return "direction"
    if group == "contact" and name in _CONTACT_ONLY:
        return "contact"
    return "ees" if name == "ees" else "heading" if name == "course_after" else None


def impulse_exchanged(result):
    """Whether an impulse was exchanged (not separating, no contact, or eps = -1): where not, the
    directions of the impulse (``undefined_kind`` "direction") are undefined."""
    return result.contact.impulse_magnitude > 0


def at_rest_after(vehicle_result):
    """Whether the vehicle's horizontal speed after the exchange is rounding (below ``REST_RATIO`` of its
    horizontal speed before plus its delta-V): then ``course_after`` is undefined."""
    after = vehicle_result.velocity_after
    before = after - vehicle_result.delta_v
    xp = _namespace(after, vehicle_result.delta_v_magnitude)
    horizontal = lambda v: xp.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2)  # noqa: E731
    return horizontal(after) <= REST_RATIO * (horizontal(before) + vehicle_result.delta_v_magnitude)


def _namespace(*arrays):
    """jax.numpy where any of ``arrays`` is a JAX array (traced in a sweep), else NumPy: a solved case's
    results are NumPy arrays, and jax.numpy on them compiled a small program per operation for every report
    (0.13-0.2 s of ``ks-jax solve``)."""
    return jnp if any(isinstance(a, jax.Array) for a in arrays) else np


def defined_output(result, path: str):
    """``get_output``, NaN where the result is undefined though the row is solved (``undefined_kind``):
    a direction of the impulse (pdof, pdof_clock, impulse_azimuth, impulse_elevation) where none was
    exchanged; the first-contact time, centroid, normal, closing and separation velocities, and EES,
    where the vehicles never touch; the course after of a vehicle at rest (``at_rest_after``). The
    exchange carries stand-in numbers there (a PDOF of 0 would read as a frontal impact), so that it never
    returns NaN and its gradients stay finite; the JSON of ``ks-jax solve`` writes them null. EES is NaN
    already where both crushes are 0 or the energy loss is negative. ``path`` may name a whole vector
    ("contact.point")."""
    group, vi, name, idx = parse_path(path)
    x = get_output(result, path) if idx else getattr(result.vehicles[vi] if group == "vehicles" else result.contact,
                                                     name)
    kind = undefined_kind(path)
    if kind == "direction":
        defined = impulse_exchanged(result)
    elif kind in ("contact", "ees"):
        defined = result.contact.status != NO_CONTACT
    elif kind == "heading":
        defined = ~at_rest_after(result.vehicles[vi])
    else:
        return x
    xp = _namespace(x, defined)
    defined = xp.reshape(defined, xp.shape(defined) + (1,) * (xp.ndim(x) - xp.ndim(defined)))
    return xp.where(defined, x, xp.nan)


def output_kind(path: str) -> str:
    """The unit kind of an output path ("degrees" for the results reported in degrees)."""
    return OUTPUT_KINDS[check_output_path(path)[2]]


def parse_output_value(value, path: str, case_name: str = "case", where: str | None = None) -> float:
    """A measured/reference value for an output path, in the unit the results use (SI, or
    degrees for pdof, impulse_azimuth, impulse_elevation, course_after)."""
    kind = output_kind(path)
    label = where or path
    if kind == "degrees":
        return _number(value, "angle", label, case_name) / U.DEG
    return _number(value, kind, label, case_name)
