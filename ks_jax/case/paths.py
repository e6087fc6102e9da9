"""Single numbers of a case's inputs and results, addressed by paths: "vehicles[1].speed",
"contact.point[0]", "vehicles[0].delta_v_body[0]" (docs/model.md, "Paths")."""

from __future__ import annotations

import dataclasses
import functools
import re

import jax
import jax.numpy as jnp
import numpy as np

from ..model.motion import RestResult
from ..model.types import ContactResult, ExchangeResult, VehicleResult
from ..units import as_typed
from .errors import CaseError, visible
from .inputs import AfterInputs, Case, CaseInputs, ContactInputs, InteractionInputs, VehicleInputs
from ..units import UnitError, parse_quantity
from .schema import INPUT_KINDS, OUTPUT_KINDS

_PATH = re.compile(r"^(vehicles|exchanges)\[(\d+)\]\.(\w+)((?:\[\d+\])*)$"
                   r"|^(contact|road|interaction)\.(\w+)((?:\[\d+\])*)$|^(energy_loss_total)$")
_APPROACH = re.compile(r"^vehicles\[(\d+)\]\.approach\[(\d+)\]\.(\w+)((?:\[\d+\])*)$")
_AT = re.compile(r"^vehicles\[(\d+)\]\.(\w+)((?:\[\d+\])*)@(.+)$")
# a vehicle's state at a time (s from the impact: "vehicles[0].speed@-2.5"), its components
AT_OUTPUTS = {"speed": 0, "position": 2, "velocity": 2, "yaw": 0, "yaw_rate": 0, "distance": 0}

class PathError(CaseError):
    pass


MAX_VEHICLES = 8  # a case's vehicles at most (``case.build``)
MAX_PHASES = 8  # an approach's phases at most (``case.approach``)
MAX_TIME = 3600.0  # s: a state at a time at most this far from the impact

def canonical_path(path: str) -> str:
    """``path`` as ``parse_path`` reads it, without spaces: "vehicles[0]. yaw" is "vehicles[0].yaw"."""
    return path.strip().replace(" ", "")

def parse_path(path: str):
    """'vehicles[1].speed' -> ('vehicles', 1, 'speed', ()); 'contact.point[0]' -> ('contact', None, 'point', (0,));
    'road.friction' -> ('road', None, 'friction', ()); 'exchanges[2].impulse_magnitude' -> ('exchanges', 2,
    'impulse_magnitude', ()); 'energy_loss_total' -> ('case', None, 'energy_loss_total', ()); a result at the start
    of an approach phase, 'vehicles[0].approach[1].position[0]' -> ('vehicles', 0, 'approach.position', (1, 0)): the
    phase's index first; a vehicle's state at a time, s from the impact (a number, or a time with its unit),
    'vehicles[0].position[1]@-2.5' -> ('vehicles', 0, 'at.position', (-2.5, 1)): the time first.
    Remembered per string: a batch of reconstructions reads the same few paths thousands of times."""
    if not isinstance(path, str):
        raise PathError(f"path {as_typed(path)}: a path is a string, e.g. 'vehicles[1].speed' or 'contact.point[0]'")
    return _parse_path(path)


@functools.lru_cache(maxsize=4096)
def _parse_path(path: str):
    t = _AT.match(canonical_path(path))
    if t:
        vi = int(t.group(1))
        if vi >= MAX_VEHICLES:
            raise PathError(f"path '{path}': vehicle index must be 0 to {MAX_VEHICLES - 1} (a case has at most "
                            f"{MAX_VEHICLES} vehicles)")
        try:
            when = parse_quantity(t.group(4), "time")
        except UnitError as err:
            raise PathError(f"path '{path}': the time after '@' ({t.group(4)}): {err}") from None
        if not np.isfinite(when) or abs(when) > MAX_TIME:
            raise PathError(f"path '{path}': the time after '@' must be finite, within +/-{MAX_TIME:g} s of the impact")
        return "vehicles", vi, f"at.{t.group(2)}", (float(when), *(int(j) for j in re.findall(r"\d+", t.group(3))))
    a = _APPROACH.match(canonical_path(path))
    if a:
        vi, k = int(a.group(1)), int(a.group(2))
        if vi >= MAX_VEHICLES or k >= MAX_PHASES:
            raise PathError(f"path '{path}': vehicle index must be 0 to {MAX_VEHICLES - 1} (a case has at most "
                            f"{MAX_VEHICLES} vehicles)" if vi >= MAX_VEHICLES else
                            f"path '{path}': phase index must be 0 to {MAX_PHASES - 1} (an approach has at most "
                            f"{MAX_PHASES} phases)")
        return "vehicles", vi, f"approach.{a.group(3)}", (k, *(int(j) for j in re.findall(r"\d+", a.group(4))))
    m = _PATH.match(canonical_path(path))
    if not m:
        raise PathError(f"path '{path}': not of the form vehicles[i].field[k], contact.field[k], road.friction, "
                        "exchanges[k].field, vehicles[i].approach[k].field or energy_loss_total")
    if m.group(8):
        return "case", None, m.group(8), ()
    if m.group(1) == "exchanges":
        return "exchanges", int(m.group(2)), m.group(3), tuple(int(k) for k in re.findall(r"\d+", m.group(4)))
    if m.group(1):
        idx = tuple(int(k) for k in re.findall(r"\d+", m.group(4)))
        vi = int(m.group(2))
        if vi >= MAX_VEHICLES:
            raise PathError(f"path '{path}': vehicle index must be 0 to {MAX_VEHICLES - 1} (a case has at most "
                            f"{MAX_VEHICLES} vehicles)")
        return "vehicles", vi, m.group(3), idx
    idx = tuple(int(k) for k in re.findall(r"\d+", m.group(7)))
    return m.group(5), None, m.group(6), idx

def input_leaf(path):
    """(group, vehicle index, field in CaseInputs, index tuple) for an input path."""
    group, vi, name, idx = parse_path(path)
    if group in ("exchanges", "case"):
        raise PathError(f"path '{path}': a result, not an input")
    if group == "interaction":
        if name not in InteractionInputs._fields or idx:
            raise PathError(f"path '{path}': the later exchanges' inputs are "
                            f"{', '.join('interaction.' + f for f in InteractionInputs._fields)}")
        return group, None, name, ()
    if group == "vehicles":
        if name == "yaw_rate" and not idx:
            return group, vi, "angular_velocity", (2,)
        if name == "inertia" and len(idx) == 1:
            if idx[0] > 2:
                raise PathError(f"path '{path}': index out of range (0..2)")
            return group, vi, "inertia", (idx[0], idx[0])
        if name in AfterInputs._fields:
            if name == "brake" and (len(idx) != 1 or idx[0] > 3):
                raise PathError(f"path '{path}': 'brake' holds four wheels' fractions: name one, brake[0] .. brake[3] "
                                "(front left, front right, rear left, rear right)")
            if name != "brake" and idx:
                raise PathError(f"path '{path}': '{name}' is a number and takes no index")
            return "road", vi, name, idx
        if name.split(".")[0] == "approach":
            raise PathError(f"path '{path}': a result of vehicles[{vi}]'s approach (its speed, time, position, yaw and "
                            "distance at a phase's start), not an input: an approach's phases are not inputs to vary")
        if name not in VehicleInputs._fields:
            hint = {"velocity": " (vary speed and course instead)",
                    "weight": f" (a case's weight sets its mass: use vehicles[{vi}].mass, in lb where weights "
                              "are in lbf)"}.get(name, "")

            raise PathError(f"path '{path}': '{name}' is not a vehicle input{hint}; "
                            f"inputs are {', '.join(VehicleInputs._fields + AfterInputs._fields)}, yaw_rate")
    elif group == "road":
        if name != "friction" or idx:
            raise PathError(f"path '{path}': the road's one input is road.friction")
        return "road", None, name, idx
    elif name not in ContactInputs._fields:
        raise PathError(f"path '{path}': '{name}' is not a contact input; "
                        f"inputs are {', '.join(ContactInputs._fields)}")
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
    input_leaf(path)
    return INPUT_KINDS[name]

def check_inputs(inputs, who: str):
    """Refuse anything but a case's inputs (a ``CaseInputs``), naming what was given: a Case, say, failed deep inside
    with "'Case' object has no attribute 'vehicles'"."""
    if not isinstance(inputs, CaseInputs):
        raise TypeError(f"{who} takes a case's inputs (case.inputs), got a {type(inputs).__name__}")


def check_result(result, who: str):
    """Refuse anything but a result (an ``ExchangeResult``), naming what was given: a Solution, say, failed deep
    inside with "'Solution' object has no attribute 'contact'"."""
    if not isinstance(result, ExchangeResult):
        raise TypeError(f"{who} takes a result (an ExchangeResult: solution.result of a Solution, or what "
                        f"solve_inputs and exchange return), got a {type(result).__name__}")


def get_input(inputs: CaseInputs, path: str):
    """The value of the input ``path`` (section 6: "vehicles[1].speed", "contact.point[0]",
    "vehicles[0].yaw_rate", ...) in ``inputs`` (a case's ``inputs``, or inputs stacked along leading axes: then
    one value per row), SI (angles in rad); a PathError names a path that is not an input. ``set_input`` is its
    converse."""
    check_inputs(inputs, "get_input")
    group, vi, name, idx = input_leaf(path)
    leaf = getattr(_holder(inputs, group, vi, path), name)
    if not idx:
        return leaf
    if isinstance(leaf, np.ndarray):  # a value on the host: read it there (no device operation per read)
        return leaf[(..., *idx)]
    return jnp.asarray(leaf)[(..., *idx)]

def set_input(inputs: CaseInputs, path: str, value, *, links=()) -> CaseInputs:
    """A copy of ``inputs`` with the number at ``path`` replaced by ``value`` (SI; traceable). A
    product of inertia (``inertia[i][j]``, i != j) sets [j][i] too: the tensor stays symmetric. ``links``: the
    case's hitches (``Motion.links``), which ``inputs`` does not hold: a towed vehicle's position (x, y), speed and
    course follow its tow's (``case.hitch.follow_tows``), and a path to them is refused."""
    check_inputs(inputs, "set_input")
    group, vi, name, idx = input_leaf(path)
    tow = next((w for t, w, _ in links if t == vi), None) if group == "vehicles" else None
    if tow is not None and _followed(name, idx):
        raise PathError(f"set_input '{path}': vehicles[{vi}] is towed by vehicles[{tow}]: {FOLLOWS}")
    try:
        dtype = None if value is None else jnp.result_type(value)
    except TypeError:
        dtype = None
    if dtype is None or not jnp.issubdtype(dtype, jnp.number) or jnp.shape(value) != ():
        raise CaseError(f"set_input '{path}' = {value!r}: the value must be one number, in SI units (for a "
                        "unit string, convert it first: ks_jax.units.parse_quantity)")
    holder = _holder(inputs, group, vi, path)
    leaf = getattr(holder, name)
    new = jnp.asarray(leaf).at[idx].set(value) if idx else value
    if name == "inertia" and len(idx) == 2 and idx[0] != idx[1]:
        new = new.at[idx[::-1]].set(value)
    holder = holder._replace(**{name: new})
    if group == "vehicles":
        vehicles = tuple(holder if i == vi else v for i, v in enumerate(inputs.vehicles))
        return inputs._replace(vehicles=vehicles)
    if group == "interaction":
        return inputs._replace(interaction=holder)
    if group == "road":
        road = inputs.road
        if vi is not None:
            road = road._replace(vehicles=tuple(holder if i == vi else v for i, v in enumerate(road.vehicles)))
        else:
            road = holder
        return inputs._replace(road=road)
    return inputs._replace(contact=holder)


def _holder(inputs: CaseInputs, group, vi, path):
    """The inputs' part that holds the leaf of ``input_leaf``'s (group, vi)."""
    if group == "vehicles":
        if vi >= len(inputs.vehicles):
            raise PathError(f"path '{path}': the case has no vehicles[{vi}] (its bodies are vehicles[0] to "
                            f"vehicles[{len(inputs.vehicles) - 1}] at most)")
        return inputs.vehicles[vi]
    if group == "contact":
        return inputs.contact
    if group == "interaction":
        if inputs.road is None:
            raise PathError(f"path '{path}': {NO_ROAD}")
        if inputs.interaction is None:  # the later exchanges take the first contact's values
            return InteractionInputs(*(getattr(inputs.contact, f) for f in InteractionInputs._fields))
        return inputs.interaction
    if inputs.road is None or (vi is not None and inputs.road.vehicles[vi] is None):
        raise PathError(f"path '{path}': {NO_ROAD}" if inputs.road is None else
                        f"path '{path}': vehicles[{vi}] is a fixed object, which does not move")
    return inputs.road if vi is None else inputs.road.vehicles[vi]


FOLLOWS = ("its position (x, y), speed and course follow its tow's through the hitch (docs/model.md, \"Articulated "
           "vehicles: the case file\"); vary its tow's, or its own yaw and yaw rate")


def _followed(name, idx) -> bool:
    """``name``[``idx``] of a towed vehicle is set by its hitch: its position's x or y, its speed or course."""
    return name in ("speed", "course") or (name == "position" and idx[:1] != (2,))


def follows_tow(case: "Case", path) -> str | None:
    """Where ``path`` names an input of ``case`` that a hitch sets (a towed vehicle's position x or y, speed or
    course: ``case.hitch.follow_tows``), so that a sweep or a fit cannot vary it (nor evidence read it): the words
    saying so, naming the tow; else None."""
    group, vi, name, idx = parse_path(path)
    links = () if case.motion is None else case.motion.links
    tow = next((w for t, w, _ in links if t == vi), None) if group == "vehicles" else None
    if tow is None or not _followed(name, idx):
        return None
    return (f"{path}: vehicles[{vi}] is towed by vehicles[{tow}] ('{visible(case.vehicle_names[tow])}'): "
            f"{FOLLOWS}")


REST_OUTPUTS = tuple(f for f in RestResult._fields if f != "path")  # a kept path is for pictures, not a number
NO_ROAD = ("the case has no road, so no motion to rest: give it one, e.g. \"road\": {\"friction\": 0.7} "
           "(docs/model.md, \"Motion to rest\")")


def without_road(case: "Case", path) -> str | None:
    """Where ``path`` names an input or result of the motion to rest (road.friction, vehicles[i].wheelbase,
    vehicles[i].rest_position[0], ...) and ``case`` has no road: the words saying so; else None."""
    group, k, name, _ = parse_path(path)
    motion = group in ("road", "interaction") or name in AfterInputs._fields or name in REST_OUTPUTS \
        or (group == "exchanges" and k > 0)
    return f"{path}: {NO_ROAD}" if motion and case.inputs is not None and case.inputs.road is None else None


APPROACH_OUTPUTS = ("speed", "time", "position", "yaw", "distance")  # at the start of each phase
NO_APPROACH = ("give it one, e.g. \"approach\": [{\"wheels\": \"locked\", \"distance\": \"48 ft\"}] (docs/model.md, "
               "\"The approach: the case file\")")


def without_approach(case: "Case", path) -> str | None:
    """Where ``path`` names a result of an approach phase (vehicles[i].approach[k].speed, ...) that ``case`` does not
    have (vehicle i has no approach, or fewer phases than k + 1): the words saying so; else None."""
    group, vi, name, idx = parse_path(path)
    if group != "vehicles" or not name.startswith("approach.") or case.inputs is None:
        return None
    kinds = () if case.motion is None else case.motion.approach
    phases = len(kinds[vi]) if vi < len(kinds) else 0
    if not phases:
        return f"{path}: vehicles[{vi}] has no approach: {NO_APPROACH}"
    if idx[0] >= phases:
        return (f"{path}: vehicles[{vi}]'s approach has {phases} phase{'s' if phases > 1 else ''} (approach[0]"
                f"{f' to approach[{phases - 1}]' if phases > 1 else ''}, earliest first)")
    return None

def automatic_part(case: "Case", path) -> str | None:
    """"point" or "normal" if ``path`` names the part of the contact that automatic contact computes
    in ``case`` (not an input there: a sweep or a fit refuses to vary it), else None."""
    _, _, name, _ = input_leaf(path)
    return name if (name == "point" and case.auto_point or name == "normal" and case.auto_normal) else None

def on_fixed_object(case: "Case", path) -> str | None:
    """Where ``path`` names a vehicle that ``case`` does not have (vehicles[i] with i at least its count of
    vehicles): the words saying why there is no input or result to vary, fit or read there (in particular where a
    fixed object takes the place of a second vehicle, docs/model.md, "Fixed objects"); else None."""
    group, vi = parse_path(path)[:2]
    n = case.vehicle_count
    if group != "vehicles" or vi < n:
        return None
    some = "vehicles[0]" if n == 1 else f"vehicles[0] to vehicles[{n - 1}]"
    if n == 1 and vi == 1 and case.fixed:
        return (f"{path}: this case strikes a fixed {case.fixed[0].kind}, which takes the place of vehicles[1]: the "
                "object has no inputs to vary and no per-vehicle results (vehicles[0] is the vehicle)")
    objects = "; its fixed objects (fixed[k]) have no inputs to vary and no per-vehicle results" if case.fixed else ""
    return f"{path}: this case has {n} vehicle{'s' if n > 1 else ''} ({some}){objects}"


def path_key(case: "Case") -> tuple:
    """All that ``get_input``, ``without_road``, ``without_approach``, ``automatic_part``, ``on_fixed_object`` and
    ``follows_tow`` read of ``case`` to accept or refuse a path: how many vehicles it has, its fixed objects' kinds,
    which of the road and its vehicles are missing, which contact parts are automatic, which vehicles are towed (by
    which), and how many approach phases each vehicle has. Cases with one key accept and refuse the same paths, so a
    batch of cases checks each path once per key."""
    road = None if case.inputs is None else case.inputs.road
    towed = () if case.motion is None else tuple((t, w) for t, w, _ in case.motion.links)
    return (case.vehicle_count, tuple(o.kind for o in case.fixed), road is None,
            () if road is None else tuple(v is None for v in road.vehicles), bool(case.auto_point),
            bool(case.auto_normal), towed,
            () if case.motion is None else tuple(len(kinds) for kinds in case.motion.approach))


def input_ties(case: "Case", paths) -> tuple:
    """((k, path), ...): the inputs that follow ``paths[k]`` when the inputs at ``paths`` are varied (a
    sweep, a fit), as re-solving the case file with the new value would move them (docs/model.md, "Inputs"):
    - a vehicle's course defaults to its yaw: where the case gives neither ``course`` nor ``velocity``
      for vehicle i, its course is still its yaw (not changed since, e.g. by ``set_input``) and
      ``vehicles[i].course`` is not among ``paths``, turning the vehicle turns its travel too;
    - a CG's height z defaults to ``cg_height``: where the case gives vehicle i a 2-D position (or none, where it
      is towed), its z is still its ``cg_height`` and neither ``vehicles[i].position[2]`` nor
      ``vehicles[i].position`` is among ``paths``, a new ``cg_height`` moves the CG to it.
    So a sweep or fit at the case's own values solves the case as it is. A towed vehicle's course follows its tow
    (``follows_tow``), not its yaw: no tie."""
    paths = [canonical_path(p) for p in paths]
    towed = set() if case.motion is None else {t for t, _, _ in case.motion.links}
    ties = []
    vehicles = case.raw.get("vehicles") if isinstance(case.raw, dict) else None
    for k, path in enumerate(paths):
        group, vi, name, _ = parse_path(path)
        if group != "vehicles" or name not in ("yaw", "cg_height"):
            continue
        raw = vehicles[vi] if isinstance(vehicles, list) and vi < len(vehicles) else {}
        raw = raw if isinstance(raw, dict) else {}
        v = case.inputs.vehicles[vi]
        if name == "yaw" and vi not in towed and "course" not in raw and "velocity" not in raw \
                and f"vehicles[{vi}].course" not in paths and np.array_equal(np.asarray(v.course), np.asarray(v.yaw)):
            ties.append((k, f"vehicles[{vi}].course"))
        position = raw.get("position")
        flat = isinstance(position, list) and len(position) == 2 or position is None and vi in towed
        if name == "cg_height" and flat \
                and not {f"vehicles[{vi}].position[2]", f"vehicles[{vi}].position"} & set(paths) \
                and np.array_equal(np.asarray(v.position)[..., 2], np.asarray(v.cg_height)):
            ties.append((k, f"vehicles[{vi}].position[2]"))
    return tuple(ties)

CUMULATIVE_OUTPUTS = ("delta_v_cumulative", "delta_v_cumulative_magnitude", "delta_v_cumulative_pdof")
VECTOR_OUTPUTS = frozenset({"point", "normal", "impulse", "closing_velocity", "separation_velocity", "delta_v",
                            "delta_v_body", "velocity_after", "angular_velocity_after", "rest_position",
                            "delta_v_cumulative"})


def check_output_path(path: str):
    """Raise PathError unless ``path`` names a number among the results (docs/model.md, "Results" and "Contact
    interactions")."""
    group, vi, name, idx = parse_path(path)
    if group in ("road", "interaction"):
        raise PathError(f"path '{path}': {group}.{name} is an input, not a result")
    if group == "case":
        return group, vi, name, idx
    if group == "vehicles" and name.split(".")[0] == "approach":
        return _check_approach_path(path, vi, name, idx)
    if group == "vehicles" and name.split(".")[0] == "at":
        return _check_at_path(path, vi, name, idx)
    fields = VehicleResult._fields + REST_OUTPUTS + CUMULATIVE_OUTPUTS if group == "vehicles" else ContactResult._fields
    kind = {"vehicles": "vehicle", "contact": "contact", "exchanges": "exchange"}[group]
    if group != "vehicles" and name == "status":
        raise PathError(f"path '{path}': the status is a code, not a number to sweep, fit or compare: read "
                        "result.contact.status (ks_jax.status_text gives its words); a sweep always returns "
                        "'status'")
    if name not in fields or name == "status":
        raise PathError(f"path '{path}': '{name}' is not a {kind} result; "
                        f"results are {', '.join(f for f in fields if f != 'status')}")
    vector = name in VECTOR_OUTPUTS
    top = 1 if name == "rest_position" else 2
    if vector and (len(idx) != 1 or idx[0] > top):
        raise PathError(f"path '{path}': '{name}' is a vector: name a component, e.g. {name}[0]"
                        if len(idx) != 1 else f"path '{path}': index out of range (0..{top})")
    if not vector and idx:
        raise PathError(f"path '{path}': '{name}' is a number and takes no index")
    return group, vi, name, idx

def _check_approach_path(path, vi, name, idx):
    """``check_output_path`` of a result of an approach phase (``parse_path``: ``name`` "approach.<field>", ``idx``
    the phase's index, then the component of a vector)."""
    field = name.partition(".")[2]
    named = ", ".join(f"vehicles[{vi}].approach[k].{f}" for f in APPROACH_OUTPUTS if f != "position")
    if not field:
        raise PathError(f"path '{path}': an approach's results are named by phase (k = 0 the earliest) and result: "
                        f"{named}, vehicles[{vi}].approach[k].position[0] or position[1]")
    if field not in APPROACH_OUTPUTS:
        raise PathError(f"path '{path}': '{field}' is not a result of an approach phase; results are "
                        f"{', '.join(APPROACH_OUTPUTS)} (at the phase's start)")
    if field == "position" and (len(idx) != 2 or idx[1] > 1):
        raise PathError(f"path '{path}': 'position' is a vector: name a component, e.g. "
                        f"vehicles[{vi}].approach[{idx[0]}].position[0]" if len(idx) != 2
                        else f"path '{path}': index out of range (0..1)")
    if field != "position" and len(idx) != 1:
        raise PathError(f"path '{path}': '{field}' is a number and takes no index")
    return "vehicles", vi, name, idx


def _check_at_path(path, vi, name, idx):
    """``check_output_path`` of a vehicle's state at a time (``parse_path``: ``name`` "at.<field>", ``idx`` the time,
    then the component of a vector)."""
    field = name.partition(".")[2]
    if field not in AT_OUTPUTS:
        raise PathError(f"path '{path}': '{field}' is not a state at a time; those are "
                        f"{', '.join(f + ('[0]' if AT_OUTPUTS[f] else '') for f in AT_OUTPUTS)} (e.g. "
                        f"vehicles[{vi}].speed@-2.5 s)")
    size = AT_OUTPUTS[field]
    if size and (len(idx) != 2 or idx[1] >= size):
        raise PathError(f"path '{path}': '{field}' is a vector: name a component, e.g. vehicles[{vi}].{field}[0]"
                        f"@{idx[0]:g}" if len(idx) != 2 else f"path '{path}': index out of range (0..{size - 1})")
    if not size and len(idx) != 1:
        raise PathError(f"path '{path}': '{field}' is a number and takes no index")
    return "vehicles", vi, name, idx


def at_time(path: str):
    """(the vehicle's index, the time in s) of a path to a vehicle's state at a time, else None."""
    group, vi, name, idx = parse_path(path)
    return (vi, idx[0]) if name.startswith("at.") else None


def times_asked(paths) -> tuple:
    """The (vehicle's index, time in s) of each of ``paths`` that names a vehicle's state at a time."""
    return tuple(w for w in (at_time(p) for p in paths) if w is not None)


def with_times(motion, paths):
    """``motion`` (a ``Motion``) with the times that ``paths`` ask states at (``Motion.times``) added to its own: the
    result's ``at`` then holds them. None stays None (``without_time`` refuses such paths)."""
    return add_times(motion, times_asked(paths))


def add_times(motion, wanted):
    """``motion`` with the times of ``wanted`` (``times_asked``'s pairs) added to its own, as ``with_times``: a batch
    whose cases share their evidence paths reads the paths once."""
    if motion is None or not wanted:
        return motion
    count = max([len(motion.times)] + [vi + 1 for vi, _ in wanted])
    times = [set(motion.times[k]) if k < len(motion.times) else set() for k in range(count)]
    for vi, t in wanted:
        times[vi].add(t)
    return dataclasses.replace(motion, times=tuple(tuple(sorted(t)) for t in times))


def without_time(case: "Case", path) -> str | None:
    """Where ``path`` names a vehicle's state at a time that ``case`` cannot give: without a road (the motion holds
    the times), or before the impact for a vehicle without an approach: the words saying so; else None."""
    group, vi, name, idx = parse_path(path)
    if group != "vehicles" or not name.startswith("at.") or case.inputs is None:
        return None
    if case.motion is None:
        return (f"{path}: a state at a time needs a road (the motion before and after the impact is worked on it; "
                "docs/model.md, \"The approach\")")
    kinds = case.motion.approach
    if idx[0] < 0 and not (vi < len(kinds) and kinds[vi]):
        return (f"{path}: vehicles[{vi}] has no approach: its state {-idx[0]:g} s before the impact is not worked; "
                "give it an \"approach\" (docs/model.md, \"The approach\")")
    return None


def get_output(result, path: str):
    """The number at an output path of a (possibly batched) ExchangeResult (of a ``Solution``: its ``result``)."""
    check_result(result, "get_output")
    group, vi, name, idx = check_output_path(path)
    if name.startswith("at."):
        return _at_output(result, path, vi, name.partition(".")[2], idx)
    leaf = output_leaf(result, path)
    return leaf[(..., *idx)] if idx else leaf


def output_leaf(result, path: str):
    """The whole result that ``path`` names a part of ("vehicles[0].rest_position[1]": the (2,) rest position;
    "vehicles[0].approach[1].speed": the speed at the start of every phase of the vehicle's approach, (P,)).

    The results of contact interactions (docs/model.md, "Contact interactions") where a case has no road, so one
    exchange: ``exchanges[0]`` is ``contact`` (its ``time`` 0), a vehicle's cumulative delta-V its delta-V, and
    ``energy_loss_total`` the energy loss."""
    group, vi, name, idx = parse_path(path)
    inter = getattr(result, "interactions", None)
    if group == "case":
        return result.contact.energy_loss if inter is None else inter.energy_loss_total
    if group == "exchanges":
        if inter is None:
            if vi > 0:
                raise PathError(f"path '{path}': {NO_ROAD}")
            return jnp.zeros_like(result.contact.energy_loss) if name == "time" else getattr(result.contact, name)
        slots = inter.exchanges.contact.energy_loss.shape[-1]
        if vi >= slots:
            raise PathError(f"path '{path}': the case keeps {slots} exchanges (exchanges[0] .. exchanges[{slots - 1}]; "
                            "interaction.max_exchanges sets how many)")
        whole = inter.time if name == "time" else getattr(inter.exchanges.contact, name)
        axis = whole.ndim - (2 if name in VECTOR_OUTPUTS else 1)  # the slots' axis, after any batch axes
        return jnp.take(whole, vi, axis=axis) if isinstance(whole, jax.Array) else np.take(whole, vi, axis=axis)
    if name in CUMULATIVE_OUTPUTS and inter is not None and vi >= inter.delta_v_cumulative.shape[-2]:
        _no_vehicle(path, vi, inter.delta_v_cumulative.shape[-2])  # an array's index past its end would clamp
    try:
        if name in CUMULATIVE_OUTPUTS:
            return _cumulative(result, inter, vi, name)
        if name.startswith("approach."):  # the result at the start of every phase: (..., P) or (..., P, 2)
            return getattr(_approach_holder(result, vi, idx[0], path), name.partition(".")[2])
        return getattr(_result_holder(result, group, vi, name, path), name)
    except IndexError:  # a tuple of the result's vehicles, shorter than the path's index
        _no_vehicle(path, vi, None)


def _no_vehicle(path, vi, count):
    """A PathError: the result holds no vehicles[vi] (``count`` of them, where known)."""
    have = "" if count is None else f" (its vehicles are vehicles[0] to vehicles[{count - 1}])"
    raise PathError(f"path '{path}': the result has no vehicles[{vi}]{have}")


def _cumulative(result, inter, vi, name):
    """A vehicle's cumulative delta-V (vector, magnitude or PDOF) over its first contact interaction; without a road,
    the delta-V of the one exchange."""
    if inter is None:
        v = result.vehicles[vi]
        return {"delta_v_cumulative": v.delta_v, "delta_v_cumulative_magnitude": v.delta_v_magnitude,
                "delta_v_cumulative_pdof": v.pdof}[name]
    dv = inter.delta_v_cumulative[..., vi, :]
    if name == "delta_v_cumulative":
        return dv
    if name == "delta_v_cumulative_pdof":
        return inter.delta_v_cumulative_pdof[..., vi]
    xp = jnp if isinstance(dv, jax.Array) else np
    return xp.sqrt(xp.sum(dv * dv, axis=-1))


def _result_holder(result, group, vi, name, path):
    """The part of ``result`` (an ExchangeResult) that holds the output ``name``."""
    if group == "contact":
        return result.contact
    if name in REST_OUTPUTS:
        if getattr(result, "rest", None) is None or result.rest[vi] is None:
            raise PathError(f"path '{path}': {NO_ROAD}" if getattr(result, "rest", None) is None else
                            f"path '{path}': vehicles[{vi}] is a fixed object, which does not move")
        return result.rest[vi]
    return result.vehicles[vi]


def _at_output(result, path, vi, field, idx):
    """Vehicle ``vi``'s ``field`` (component ``idx[1:]``) at the time ``idx[0]`` in ``result.at``."""
    at = getattr(result, "at", None)
    if at is None or vi >= len(at) or at[vi] is None:
        raise PathError(f"path '{path}': the result holds no states at a time of vehicles[{vi}]: solve the case "
                        "with those times in case.motion.times (ks_jax.case.with_times; a sweep or a fit does so)")
    time = at[vi].time
    if isinstance(time, jax.Array):  # inside a program: the times are the case's, the same in every row
        j = jnp.argmin(jnp.abs(time.reshape(-1, time.shape[-1])[0] - idx[0]))
    else:
        times = np.asarray(time).reshape(-1, time.shape[-1])[0]
        found = np.flatnonzero(times == idx[0])
        if not found.size:
            raise PathError(f"path '{path}': vehicles[{vi}]'s states are at {', '.join(f'{t:g}' for t in times)} s, "
                            f"not at {idx[0]:g} s")
        j = int(found[0])
    leaf = getattr(at[vi], field)
    axis = leaf.ndim - (2 if AT_OUTPUTS[field] else 1)
    value = jnp.take(leaf, j, axis=axis) if isinstance(leaf, jax.Array) else np.take(leaf, j, axis=axis)
    return value[..., idx[1]] if AT_OUTPUTS[field] else value


def _approach_holder(result, vi, k, path):
    """Vehicle ``vi``'s ``model.approach.ApproachResult`` in ``result``, which must have phase ``k``."""
    approach = getattr(result, "approach", None)
    if approach is None or vi >= len(approach) or approach[vi] is None:
        raise PathError(f"path '{path}': vehicles[{vi}] has no approach: {NO_APPROACH}")
    phases = approach[vi].time.shape[-1]
    if k >= phases:
        raise PathError(f"path '{path}': vehicles[{vi}]'s approach has {phases} phase{'s' if phases > 1 else ''} "
                        f"(approach[0] to approach[{phases - 1}])")
    return approach[vi]


def output_kind(path: str) -> str:
    """The unit kind of an output path ("degrees" for the results reported in degrees); an exchange's time is a time
    like the contact's."""
    return OUTPUT_KINDS[check_output_path(path)[2]]
