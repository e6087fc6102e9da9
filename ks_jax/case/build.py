"""A case as a dict (as a JSON or TOML file gives it) into a ``Case`` (docs/model.md, "Case files"): every section's
fields checked and converted to SI. Units exist only at this edge: every number is converted to SI here.

Errors name the case, the field path, the value and the rule, and raise ``CaseError``. Reading the files, with
their limits, and keeping a bad case of several as an invalid ``Case`` is ``load``'s.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from .. import units as U
from .approach import read_approach
from .crush import crush_energies, read_crush
from .errors import CaseError, CaseWarning
from ..model.motion import MAX_FRICTION as MAX_ROAD_FRICTION
from ..model.motion import TIME_LIMIT as MOTION_LIMIT
from ..model.motion import TIME_STEP as MOTION_STEP
from .fields import repeated as _repeated, text as _text
from .fields import both as _both, check_keys as _check_keys, given as _given, limit as _limit, number as _number
from .fields import positive as _positive, require as _require, shown as _shown, typed_scale as _typed_scale
from .fields import vector as _vector, where as _where
from .fixed import KINDS, OBJECT_HEIGHT, FixedObject, object_inputs
from .hitch import check_between, check_fifth_wheels, check_pairs, follow_vehicles, need_road, read_hitches
from .inputs import AfterInputs, Case, CaseInputs, ContactInputs, InteractionInputs, Motion, PairInputs, RoadInputs
from .inputs import VehicleInputs
from .paths import check_output_path, output_kind
from .schema import AFTER_FIELDS, CASE_FIELDS, CONTACT_FIELDS, INTERACTION_FIELDS, ROAD_FIELDS, TEXT_FIELDS
from .schema import VEHICLE_FIELDS
from .wheels import running


def _inertia(value, path, case_name):
    if isinstance(value, (list, tuple)) and len(value) == 3 and all(isinstance(r, (list, tuple)) for r in value):
        m = np.array([_vector(r, "inertia", f"{path}[{i}]", case_name, (3,)) for i, r in enumerate(value)])
        if not np.allclose(m, m.T, rtol=1e-9, atol=0):
            raise CaseError(f"{_where(case_name, path)} = {value!r}: an inertia tensor must be symmetric")
        if np.any(np.linalg.eigvalsh(m) <= 0):
            raise CaseError(f"{_where(case_name, path)} = {_shown(value)}: an inertia tensor must be positive definite")
        _at_least(float(np.min(np.linalg.eigvalsh(m))), MIN_INERTIA, value, path, case_name, "kg m^2 (its least "
                  "principal moment)")
        return m
    moments = _vector(value, "inertia", path, case_name, (3,))
    for i, x in enumerate(moments):
        if x <= 0:
            raise CaseError(f"{_where(case_name, path)}[{i}] = {value[i]!r}: "
                            "principal moments of inertia must be positive")
        _at_least(x, MIN_INERTIA, value[i], f"{path}[{i}]", case_name, "kg m^2", "inertia")
    return np.diag(moments)


# The least mass and moment of inertia a vehicle may have: the exchange inverts them (and the inertia's
# determinant, a product of three moments), which smaller values would overflow (docs/model.md, "Limits")
MIN_MASS = 1e-3  # kg
MIN_INERTIA = 1e-3  # kg m^2


def _at_least(x, least, raw, path, case_name, unit, kind=None):
    if x < least:
        shown = _given(raw, x, kind) if kind else _shown(raw)
        raise CaseError(f"{_where(case_name, path)} = {shown}: must be at least {least:g} {unit}; the exchange "
                        "divides by it")


def _vehicle_inputs(d, i, case_name):
    path = f"vehicles[{i}]"
    _check_keys(d, set(VEHICLE_FIELDS) | TEXT_FIELDS, path, case_name)
    num = lambda k: _number(d[k], VEHICLE_FIELDS[k][0], f"{path}.{k}", case_name)  # noqa: E731
    if "mass" in d and "weight" in d:
        raise CaseError(f"{_where(case_name, path)}: give mass or weight, not both")
    if "mass" in d:
        mass = num("mass")
        _positive(mass, d["mass"], f"{path}.mass", case_name, "mass must be positive")
        _at_least(mass, MIN_MASS, d["mass"], f"{path}.mass", case_name, "kg", "mass")
    elif "weight" in d:
        mass = num("weight") / U.G0
        _positive(mass, d["weight"], f"{path}.weight", case_name, "weight must be positive")
        _at_least(mass, MIN_MASS, d["weight"], f"{path}.weight", case_name, "kg of mass")
    else:
        raise CaseError(f"{_where(case_name, path + '.mass')}: missing field (give mass or weight)")
    inertia = _inertia(_require(d, "inertia", path, case_name), f"{path}.inertia", case_name)
    dims = {}
    for k in ("length", "width", "height", "cg_to_front", "cg_height"):
        _require(d, k, path, case_name)
        dims[k] = num(k)
    for k in ("length", "width", "height"):
        _positive(dims[k], d[k], f"{path}.{k}", case_name, f"{k} must be positive")
    for k, whole in (("cg_to_front", "length"), ("cg_height", "height")):
        if not 0 <= dims[k] <= dims[whole]:
            raise CaseError(f"{_where(case_name, f'{path}.{k}')} = {_given(d[k], dims[k], 'length')}: must be "
                            f"between 0 and {_limit('the ' + whole, d[whole], dims[whole], 'length')}")
    towed = "hitch" in d  # its position and velocity follow its tow's (``hitch.follow_vehicles``): optional here
    pos = [math.nan, math.nan] if towed and "position" not in d else \
        _vector(_require(d, "position", path, case_name), "length", f"{path}.position", case_name, (2, 3))
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
    elif towed:
        if "course" in d:
            raise CaseError(f"{_where(case_name, path + '.course')} = {_shown(d['course'])}: given without speed; a "
                            "towed vehicle's speed and course follow its tow's: give both (checked against what "
                            "follows) or neither")
        speed, course, vz = math.nan, math.nan, 0.0
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
                raise CaseError(f"{_where(case_name, 'contact.normal')} = {raw!r}: "
                                "the normal must be a non-zero vector")
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
        raise CaseError(f"case '{default_name}': a case must be an object/table, got {_shown(d)}")
    name = _text(d, "name", default_name, "name", default_name)  # as given: JSON carries it, the terminal escapes it
    _repeated(d, "", name)
    _check_keys(d, CASE_FIELDS, "", name)
    vehicles = _require(d, "vehicles", "", name) if "vehicles" in d else None
    if vehicles is None:
        raise CaseError(f"{_where(name, 'vehicles')}: missing field")
    if not isinstance(vehicles, list) or not 1 <= len(vehicles) <= MAX_VEHICLES:
        given = f": {len(vehicles)} given" if isinstance(vehicles, list) else f" = {_shown(vehicles)}: not a list"
        raise CaseError(f"{_where(name, 'vehicles')}{given}; a case has 1 to {MAX_VEHICLES} vehicles")
    listed = d.get("fixed", [])
    if isinstance(listed, dict):
        objects_raw, where = [listed], lambda k: "fixed"
    elif isinstance(listed, list) and len(listed) <= MAX_FIXED:
        objects_raw, where = listed, lambda k: f"fixed[{k}]"
    else:
        given = f": {len(listed)} given" if isinstance(listed, list) else f" = {_shown(listed)}"
        raise CaseError(f"{_where(name, 'fixed')}{given}; must be one fixed object or a list of at most {MAX_FIXED}, "
                        "e.g. {\"kind\": \"wall\", \"point\": [0, 0], \"normal\": 180}")
    if len(vehicles) + len(objects_raw) < 2:
        raise CaseError(f"{_where(name, 'vehicles')}: 1 given and no fixed object; a case needs two bodies: two "
                        "vehicles, or a vehicle and a fixed object (\"fixed\")")
    if "contact" not in d:
        raise CaseError(f"{_where(name, 'contact')}: missing field")
    veh = tuple(_vehicle_inputs(v, i, name) for i, v in enumerate(vehicles))
    links, hitches = read_hitches(vehicles, name)
    need_road(d, links, name)
    veh = follow_vehicles(vehicles, veh, links, hitches, name)
    objects = tuple(_fixed_object(o, name, where(k)) for k, o in enumerate(objects_raw))
    bodies = veh + tuple(object_inputs(o, veh) for o in objects)
    between = _between(d.get("between"), len(veh), len(objects), name)
    check_between(d.get("between"), between, links, name)
    contact, auto_point, auto_normal = _contact_inputs(d["contact"], name)
    if "reference" in d:
        _check_reference(d["reference"], name)
    if "road" not in d and len(bodies) > 2:
        raise CaseError(f"{_where(name, 'road')}: missing field; a case of more than two bodies needs a road: the "
                        "exchanges after the first happen while the bodies move on (add \"road\": {\"friction\": "
                        "0.7}; docs/model.md, \"Contact interactions\")")
    road, motion = _road(d, bodies, len(veh), name)
    check_fifth_wheels(vehicles, links, hitches, name)
    interaction, motion = _interaction(d, motion, contact, objects, len(veh), name)
    pairs, motion = _pairs(d, motion, contact if interaction is None else interaction, len(veh), len(objects),
                          name)
    if links:
        check_pairs(d.get("pairs"), motion.pairs, links, name)
        motion = dataclasses.replace(motion, links=links)
    approach, kinds = read_approach(vehicles, road, links, name)
    motion = dataclasses.replace(motion, approach=kinds) if kinds else motion
    crush = read_crush(vehicles, [(float(v.length), float(v.width)) for v in veh], name)
    inputs = CaseInputs(bodies, contact, road, interaction, pairs, hitches, approach, crush_energies(crush, objects))
    names = tuple(_text(v, "name", f"vehicle {i + 1}", f"vehicles[{i}].name", name) for i, v in enumerate(vehicles))
    names += tuple(_text(o, "name", o["kind"], f"{where(k)}.name", name) for k, o in enumerate(objects_raw))
    return Case(name, inputs, auto_point, auto_normal, names, None, d, source, objects, motion, between, crush)


MAX_VEHICLES = 8  # vehicles in a case at most (docs/model.md, "Contact interactions")
MAX_FIXED = 8  # fixed objects in a case at most


def _body(value, vehicles, objects, path, case_name, vehicle_only=False) -> int:
    """A body named in a case file as a vehicle's index (0, 1, ...) or "fixed[k]": its index among the case's
    bodies (the vehicles, then the fixed objects)."""
    if isinstance(value, int) and not isinstance(value, bool) and 0 <= value < vehicles:
        return value
    if isinstance(value, str) and not vehicle_only:
        text = value.replace(" ", "")
        if text.startswith("fixed[") and text.endswith("]") and text[6:-1].isdigit() and int(text[6:-1]) < objects:
            return vehicles + int(text[6:-1])
    some = f"0 to {vehicles - 1}" if vehicles > 1 else "0"
    last = f' to "fixed[{objects - 1}]"' if objects > 1 else ""
    fixed = "" if vehicle_only or not objects else f', or "fixed[0]"{last} for a fixed object'
    rule = "the first body must be a vehicle" if vehicle_only else "no such body"
    raise CaseError(f"{_where(case_name, path)} = {_shown(value)}: {rule}; name a vehicle by its index ({some}){fixed}")


def _between(value, vehicles, objects, case_name) -> tuple:
    """The bodies of the first exchange (``Case.between``): "between": [i, j], default [0, 1], or [0, "fixed[0]"]
    for a case of one vehicle."""
    if value is None:
        return (0, 1)
    if not isinstance(value, list) or len(value) != 2:
        raise CaseError(f"{_where(case_name, 'between')} = {_shown(value)}: must name the first exchange's two bodies, "
                        "e.g. [0, 1] or [0, \"fixed[0]\"]")
    i = _body(value[0], vehicles, objects, "between[0]", case_name, vehicle_only=True)
    j = _body(value[1], vehicles, objects, "between[1]", case_name)
    if i == j:
        raise CaseError(f"{_where(case_name, 'between')} = {_shown(value)}: a body cannot strike itself")
    return (i, j)

# Defaults of a vehicle's wheels where the file gives none (docs/model.md, "Motion to rest"): a passenger car's
# proportions
WHEELBASE_SHARE = 0.6  # of the length
TRACK_SHARE = 0.85  # of the width
MAX_STEPS = 1_000_000  # time_limit / time_step


def _road(d, bodies, vehicles, case_name):
    """(RoadInputs, Motion) of a case with a ``road``, else (None, None) (docs/model.md, "Motion to rest")."""
    if "road" not in d:
        for i, v in enumerate(d["vehicles"]):
            given = [k for k in ("wheelbase", "track", "cg_to_front_axle", "after") if isinstance(v, dict) and k in v]
            if given:
                warnings.warn(CaseWarning(f"{_where(case_name, f'vehicles[{i}]')}: {', '.join(given)} describe the "
                                          "motion to rest, which a case without \"road\" does not have: ignored "
                                          "(add \"road\": {\"friction\": 0.7})"), stacklevel=3)
        return None, None
    road = d["road"]
    _check_keys(road, set(ROAD_FIELDS) | TEXT_FIELDS, "road", case_name)
    num = lambda k: _number(road[k], ROAD_FIELDS[k][0], f"road.{k}", case_name)  # noqa: E731
    friction = num("friction") if "friction" in road else None
    if friction is None:
        raise CaseError(f"{_where(case_name, 'road.friction')}: missing field (the tyre-road friction, e.g. 0.7)")
    if not 0 <= friction <= MAX_ROAD_FRICTION:
        raise CaseError(f"{_where(case_name, 'road.friction')} = {_shown(road['friction'])}: must be >= 0 (0: a "
                        f"frictionless plane, on which the motion runs to its time limit) and at most "
                        f"{MAX_ROAD_FRICTION:g} (no tyre grips more)")
    dt = num("time_step") if "time_step" in road else MOTION_STEP
    if not 0 < dt <= 0.05:
        raise CaseError(f"{_where(case_name, 'road.time_step')} = {_given(road['time_step'], dt, 'time')}: must be "
                        "in (0, 0.05] s")
    limit = num("time_limit") if "time_limit" in road else MOTION_LIMIT
    if not 0 < limit <= 600:
        raise CaseError(f"{_where(case_name, 'road.time_limit')} = {_given(road['time_limit'], limit, 'time')}: must "
                        "be in (0, 600] s")
    if limit / dt > MAX_STEPS:
        raise CaseError(f"{_where(case_name, 'road')}: time_limit / time_step = {limit / dt:.4g} steps, more than "
                        f"{MAX_STEPS}: lengthen the step or shorten the limit")
    after = tuple(_after(d["vehicles"][i], v, i, friction, case_name) for i, v in enumerate(bodies[:vehicles]))
    after += (None,) * (len(bodies) - vehicles)  # a fixed object does not move
    return RoadInputs(friction, after), Motion(float(dt), float(limit))


MAX_EXCHANGES_LIMIT = 64  # a case's max_exchanges at most (each is a slot of results in every solved row)


def _interaction(d, motion, contact, objects, vehicles, case_name):
    """(``InteractionInputs`` or None, the ``Motion`` with the watched motion's settings) of a case's
    ``interaction`` entry (docs/model.md, "Contact interactions"): the later exchanges' restitution, friction and
    penetration time (default: the first contact's), ``approach_tolerance`` and ``max_exchanges``. Later
    exchanges happen during the motion to rest: without a ``road`` the entry is ignored, with a warning."""
    poles = tuple(vehicles + k for k, o in enumerate(objects) if o.kind == "pole")
    if "interaction" not in d:
        return None, None if motion is None else dataclasses.replace(motion, poles=poles)
    entry = d["interaction"]
    if not isinstance(entry, dict):
        raise CaseError(f"{_where(case_name, 'interaction')} = {_shown(entry)}: must be an object/table of "
                        f"{', '.join(INTERACTION_FIELDS)}")
    _check_keys(entry, set(INTERACTION_FIELDS) | TEXT_FIELDS, "interaction", case_name)
    if motion is None:
        warnings.warn(CaseWarning(f"{_where(case_name, 'interaction')}: later exchanges happen while the bodies move "
                                  "on, which a case without \"road\" does not do: ignored (add \"road\": "
                                  "{\"friction\": 0.7})"), stacklevel=3)
        return None, None
    path = lambda k: f"interaction.{k}"  # noqa: E731
    values = _exchange_values(entry, ("restitution", "friction", "penetration_time", "approach_tolerance"),
                              "interaction", case_name)
    most = entry.get("max_exchanges", motion.max_exchanges)
    if isinstance(most, bool) or not isinstance(most, int) or not 1 <= most <= MAX_EXCHANGES_LIMIT:
        raise CaseError(f"{_where(case_name, path('max_exchanges'))} = {_shown(most)}: must be a whole number from 1 "
                        f"to {MAX_EXCHANGES_LIMIT} (the first exchange included)")
    motion = dataclasses.replace(motion, max_exchanges=most, poles=poles,
                                 approach_tolerance=float(values.get("approach_tolerance", motion.approach_tolerance)))
    own = [k for k in InteractionInputs._fields if k in values]
    if not own:
        return None, motion
    return InteractionInputs(*(values.get(k, getattr(contact, k)) for k in InteractionInputs._fields)), motion


_EXCHANGE_RULES = {"restitution": (lambda x: -1 <= x <= 1, "must be in [-1, 1]"),
                   "friction": (lambda x: x >= 0, "must be >= 0"),
                   "penetration_time": (lambda x: x >= 0, "must be >= 0 s"),
                   "approach_tolerance": (lambda x: x > 0, "must be positive (below it a pair is not approaching)")}


def _exchange_values(entry, fields, where, case_name) -> dict:
    """The SI values of ``fields`` that ``entry`` (an "interaction" or a "pairs" entry at ``where``) gives, each
    checked against its rule."""
    values = {}
    for k in fields:
        if k in entry:
            values[k] = _number(entry[k], INTERACTION_FIELDS[k][0], f"{where}.{k}", case_name)
            if not _EXCHANGE_RULES[k][0](values[k]):
                raise CaseError(f"{_where(case_name, f'{where}.{k}')} = {_shown(entry[k])}: {_EXCHANGE_RULES[k][1]}")
    return values


PAIR_FIELDS = ("between", "restitution", "friction", "penetration_time")


def _pairs(d, motion, later, vehicles, objects, case_name):
    """(a ``PairInputs`` per entry, the ``Motion`` with their pairs) of a case's ``pairs`` (docs/model.md, "Contact
    interactions"): the later exchanges of one pair with values of their own; what an entry does not give is the
    case's (``later``: its ``InteractionInputs``, else its first ``ContactInputs``). Without a road the entry is
    ignored, with a warning."""
    if "pairs" not in d:
        return (), motion
    entries = d["pairs"]
    if motion is None:
        warnings.warn(CaseWarning(f"{_where(case_name, 'pairs')}: later exchanges happen while the bodies move on, "
                                  "which a case without \"road\" does not do: ignored (add \"road\": {\"friction\": "
                                  "0.7})"), stacklevel=3)
        return (), motion
    if not isinstance(entries, list):
        raise CaseError(f"{_where(case_name, 'pairs')} = {_shown(entries)}: must be a list of pairs, e.g. "
                        "[{\"between\": [1, 2], \"restitution\": 0.1}]")
    out, which = [], []
    for n, entry in enumerate(entries):
        where = f"pairs[{n}]"
        _check_keys(entry, set(PAIR_FIELDS) | TEXT_FIELDS, where, case_name)
        between = _require(entry, "between", where, case_name)
        if not isinstance(between, list) or len(between) != 2:
            raise CaseError(f"{_where(case_name, where + '.between')} = {_shown(between)}: must name two bodies, e.g. "
                            "[1, 2] or [0, \"fixed[0]\"]")
        i, j = sorted(_body(b, vehicles, objects, f"{where}.between[{k}]", case_name) for k, b in enumerate(between))
        if i == j or i >= vehicles:
            raise CaseError(f"{_where(case_name, where + '.between')} = {_shown(between)}: "
                            + ("a body cannot strike itself" if i == j else "two fixed objects never meet"))
        if (i, j) in which:
            raise CaseError(f"{_where(case_name, where + '.between')} = {_shown(between)}: "
                            f"pairs[{which.index((i, j))}] names the same pair")
        values = _exchange_values(entry, PairInputs._fields, where, case_name)
        out.append(PairInputs(*(values.get(k, getattr(later, k)) for k in PairInputs._fields)))
        which.append((i, j))
    return tuple(out), dataclasses.replace(motion, pairs=tuple(which))


def _after(d, v: VehicleInputs, i, friction, case_name) -> AfterInputs:
    """Vehicle i's ``AfterInputs``: its wheels' places (defaults: ``WHEELBASE_SHARE``, ``TRACK_SHARE``, the
    axles set in equally from the ends) and ``after`` (default: free rolling, no steer)."""
    path = f"vehicles[{i}]"
    num = lambda k: _number(d[k], VEHICLE_FIELDS[k][0], f"{path}.{k}", case_name)  # noqa: E731
    length, width = float(v.length), float(v.width)
    wheelbase = num("wheelbase") if "wheelbase" in d else WHEELBASE_SHARE * length
    raw = {k: d.get(k) for k in ("length", "width", "cg_to_front", "wheelbase")}  # as typed, for the messages
    if not 0 < wheelbase <= length:
        raise CaseError(f"{_where(case_name, path + '.wheelbase')} = {_given(d['wheelbase'], wheelbase, 'length')}: "
                        f"must be positive and at most {_limit('the length', raw['length'], length, 'length')}")
    track = num("track") if "track" in d else TRACK_SHARE * width
    if not 0 < track <= width:
        raise CaseError(f"{_where(case_name, path + '.track')} = {_given(d['track'], track, 'length')}: must be "
                        f"positive and at most {_limit('the width', raw['width'], width, 'length')}")
    a = num("cg_to_front_axle") if "cg_to_front_axle" in d else float(v.cg_to_front) - 0.5 * (length - wheelbase)
    where = path + ".cg_to_front_axle"
    shown = (_given(d["cg_to_front_axle"], a, "length") if "cg_to_front_axle" in d
             else f"{a:.4g} m (from its defaults)")
    if not 0 < a < wheelbase:
        raise CaseError(f"{_where(case_name, where)} = {shown}: the CG must lie between the axles: "
                        f"0 < cg_to_front_axle < {_limit('wheelbase', raw['wheelbase'], wheelbase, 'length')}")
    if a > float(v.cg_to_front) + 1e-9 or wheelbase - a > length - float(v.cg_to_front) + 1e-9:
        rear_typed = raw["length"] if _typed_scale(raw["length"], "length") else raw["cg_to_front"]
        behind = _both(rear_typed, length - float(v.cg_to_front), "length").replace(", ", " (", 1)
        behind += ")" if "(" in behind else ""
        ahead = _limit("cg_to_front", raw["cg_to_front"], float(v.cg_to_front), "length")
        raise CaseError(f"{_where(case_name, where)} = {shown}: the axles must lie within the vehicle's length "
                        f"(front axle at most {ahead} ahead of the CG, rear axle at most {behind} behind it)")
    after = d.get("after", {})
    _check_keys(after, set(AFTER_FIELDS) | TEXT_FIELDS, path + ".after", case_name)
    brake, steer, f = running(after, path + ".after", friction, case_name)
    return AfterInputs(wheelbase, track, a, np.array(brake, dtype=float), steer, f)


FIXED_FIELDS = {"wall": {"point": ("length", "vec2"), "normal": ("angle", None)},
                "pole": {"position": ("length", "vec2"), "diameter": ("length", None)},
                "barrier": {"position": ("length", "vec2"), "yaw": ("angle", None), "length": ("length", None),
                            "width": ("length", None), "height": ("length", None)}}


def _fixed_object(d, case_name, path="fixed") -> FixedObject:
    """A fixed object of a case's ``fixed`` entry (docs/model.md, "Fixed objects"), SI; ``path``: where it is
    ("fixed", or "fixed[k]" in a list)."""
    if not isinstance(d, dict):
        raise CaseError(f"{_where(case_name, path)} = {_shown(d)}: must be a table/object, e.g. "
                        "{\"kind\": \"wall\", \"point\": [0, 0], \"normal\": 180}")
    kind = _require(d, "kind", path, case_name)
    if kind not in KINDS:
        raise CaseError(f"{_where(case_name, path + '.kind')} = {_shown(kind)}: must be one of {', '.join(KINDS)}")
    fields = FIXED_FIELDS[kind]
    _check_keys(d, set(fields) | TEXT_FIELDS | {"kind"}, path, case_name)
    values = {}
    for k, (quantity, shape) in fields.items():
        if k == "height" and k not in d:
            values[k] = OBJECT_HEIGHT
            continue
        raw = _require(d, k, path, case_name)
        where = f"{path}.{k}"
        values[k] = np.array(_vector(raw, quantity, where, case_name, (2,))) if shape else _number(raw, quantity, where,
                                                                                                    case_name)
    for k in ("diameter", "length", "width", "height"):
        if k in values:
            _positive(values[k], d.get(k, values[k]), f"{path}.{k}", case_name, f"{k} must be positive")
    return FixedObject(kind, **values)

def _check_reference(reference, case_name):
    """``reference``: reported results to print beside ks-jax's (an output path -> its value, e.g. the
    manual's panel); checked when the case is read, so that a bad entry costs its case only."""
    if not isinstance(reference, dict):
        raise CaseError(f"{_where(case_name, 'reference')} = {_shown(reference)}: must map output paths to reported "
                        "values, e.g. {\"contact.impulse_magnitude\": \"1336.904 lbf*s\"}")
    for path, value in reference.items():
        try:
            check_output_path(path)
        except CaseError as err:
            raise CaseError(f"{_where(case_name, 'reference')}: {err}") from None
        parse_output_value(value, path, case_name, f"reference.{path}")


def parse_output_value(value, path: str, case_name: str = "case", where: str | None = None) -> float:
    """A measured/reference value for an output path, in the unit the results use (SI, or
    degrees for pdof, impulse_azimuth, impulse_elevation, course_after)."""
    kind = output_kind(path)
    label = where or path
    if kind == "degrees":
        return _number(value, "angle", label, case_name) / U.DEG
    return _number(value, kind, label, case_name)
