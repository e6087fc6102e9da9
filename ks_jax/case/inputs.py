"""A case's inputs as one pytree of SI arrays (``CaseInputs``), and the kernel's pytrees made from it.

``CaseInputs`` holds every scalar a user may vary, sweep or fit, in the form case files give them
(speed and course rather than a velocity vector, a normal's azimuth and pitch). ``to_pytrees`` turns it
into the physics' (Vehicle, State, Vehicle, State, Contact) of the first exchange's pair of bodies; ``body_states``
gives every body's ``State``.
"""

from __future__ import annotations

import functools
import operator
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ..model import linalg as la
from ..model.types import Contact, State, Vehicle, normal_from_angles


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

class AfterInputs(NamedTuple):
    """One vehicle's inputs to its motion after the exchange, SI: where its wheels are (``wheelbase``,
    ``track``, ``cg_to_front_axle``, m) and how they run (``brake`` (4,) in [0, 1] per wheel: front left,
    front right, rear left, rear right, 0 free, 1 locked; ``steer`` rad, the front wheels' angle, left +;
    ``rolling_resistance``)."""

    wheelbase: Any
    track: Any
    cg_to_front_axle: Any
    brake: Any
    steer: Any
    rolling_resistance: Any

class RoadInputs(NamedTuple):
    """The road the vehicles move on to rest: ``friction`` (mu), and each vehicle's ``AfterInputs`` (None for a
    fixed object, which does not move)."""

    friction: Any
    vehicles: tuple

class InteractionInputs(NamedTuple):
    """The exchanges after the first (docs/model.md, "Contact interactions"), SI: ``restitution``, ``friction``,
    ``penetration_time`` (s)."""

    restitution: Any
    friction: Any
    penetration_time: Any

class PairInputs(NamedTuple):
    """The later exchanges of one pair of bodies (a case's ``pairs`` entry), SI: ``restitution``, ``friction``,
    ``penetration_time`` (s); which pair it is, is ``Motion.pairs``."""

    restitution: Any
    friction: Any
    penetration_time: Any

class HitchInputs(NamedTuple):
    """One hitch (docs/model.md, "Articulated vehicles"), SI: ``point`` (2,) m, the hitch in the towed vehicle's
    body frame; ``point_on_tow`` (2,) m, the same hitch in its tow's body frame; ``max_angle`` () rad, the largest
    articulation (the towed vehicle's yaw minus its tow's) either way, inf for none. Which vehicles it couples, and
    how, is ``Motion.links``."""

    point: Any
    point_on_tow: Any
    max_angle: Any

class ApproachInputs(NamedTuple):
    """One vehicle's approach phases (docs/model.md, "The approach"), earliest first, SI, stacked (P, ...): ``brake``
    (P, 4) per wheel in [0, 1] (as ``AfterInputs.brake``), ``steer`` (P,) rad, ``rolling_resistance`` (P,),
    ``friction`` (P,) the road's in each phase, ``length`` (P,): s for a phase by duration, m for one by distance
    (which each is, is ``Motion.approach``)."""

    brake: Any
    steer: Any
    rolling_resistance: Any
    friction: Any
    length: Any

class CaseInputs(NamedTuple):
    """``vehicles``: a ``VehicleInputs`` per body, the case's vehicles (1 to 8) and then its fixed objects (0 to 8,
    each a box at rest of infinite mass, ``case.fixed.object_inputs``); ``contact``: ``ContactInputs``; ``road``:
    ``RoadInputs``, or None for a case without motion to rest; ``interaction``: ``InteractionInputs`` where the case
    sets the later exchanges' own values, None where they are the first contact's; ``pairs``: a ``PairInputs`` for
    each pair of ``Motion.pairs``, whose own values take the place of the case's; ``hitches``: a ``HitchInputs`` for
    each link of ``Motion.links``; ``approach``: () for a case without one, else one entry per vehicle, an
    ``ApproachInputs`` or None for a vehicle without; ``crush_energy``: () for a case without crush profiles, else per
    body the energy (J) its measured crush absorbed (docs/model.md, "Crush energy"), or None for a body without one:
    where both bodies of the first exchange have one, its energy loss is shared between them in proportion to
    these rather than to the box overlap's crushes."""

    vehicles: tuple
    contact: ContactInputs
    road: Any = None
    interaction: Any = None
    pairs: tuple = ()
    hitches: tuple = ()
    approach: tuple = ()
    crush_energy: tuple = ()

@dataclass(frozen=True)
class Motion:
    """How a case's motion to rest is integrated (static: each setting compiles a program of its own):
    ``time_step`` and ``time_limit``, s; ``path``: keep each vehicle's state after every step (for a picture:
    ``ks_jax.solve.motion_paths``); ``reverse``: ready for reverse-mode differentiation (``jax.grad``, first order),
    which runs every step to the time limit (``model.motion_loop.to_rest``); forward mode (``jax.jacfwd``, as fits use)
    needs it False. The watched motion's settings (docs/model.md, "Contact interactions";
    ``model.interaction.interact``): ``max_exchanges`` per case, the first included; ``approach_tolerance`` m/s;
    ``poles``: the bodies that automatic contact meets as a pole's disc; ``pairs``: the pairs of bodies (i, j),
    i < j, whose later exchanges have values of their own (``CaseInputs.pairs``); ``links``: the hitches
    (docs/model.md, "Articulated vehicles"), each ``(towed, tow, kind)``: the two vehicles' indices and "drawbar"
    (the towed vehicle stands on its own wheels) or "fifth_wheel" (its front is carried by the tow at the hitch),
    a tow always listed before the vehicles it tows; their points are ``CaseInputs.hitches``. ``approach``: () for a
    case without one, else per vehicle the kinds of its approach phases, each "duration" or "distance" (() for a
    vehicle without); their values are ``CaseInputs.approach``. ``times``: () or per vehicle the times (s from the
    impact, sorted) at which the result's ``at`` gives its state (docs/model.md, "The approach")."""

    time_step: float
    time_limit: float
    path: bool = False
    reverse: bool = False
    max_exchanges: int = 16
    approach_tolerance: float = 0.05
    poles: tuple = ()
    pairs: tuple = ()
    links: tuple = ()
    approach: tuple = ()
    times: tuple = ()

@dataclass(frozen=True)
class Case:
    """One case: its name, its inputs (None if invalid), and which contact parts are automatic. ``fixed``: the
    case's ``case.fixed.FixedObject``s, in file order (empty for none); their inputs follow the vehicles' in
    ``inputs.vehicles``, boxes at rest of infinite mass. ``vehicle_names``: every body's name, the vehicles' and then
    the fixed objects'. ``between``: the bodies of the first exchange (indices into ``inputs.vehicles``: its vehicle
    1 and vehicle 2). ``motion``: the integration's settings where the case has a ``road`` (its vehicles move on to
    rest), else None. ``crush``: each vehicle's measured crush and stiffness (a ``case.crush.CrushProfile``, or None
    for a vehicle without), () where no vehicle has one."""

    name: str
    inputs: CaseInputs | None
    auto_point: bool = False
    auto_normal: bool = False
    vehicle_names: tuple = ("vehicle 1", "vehicle 2")
    error: str | None = None
    raw: dict = field(default_factory=dict, compare=False, repr=False)
    source: str | None = None
    fixed: tuple = ()
    motion: Motion | None = None
    between: tuple = (0, 1)
    crush: tuple = ()

    @property
    def valid(self) -> bool:
        return self.error is None

    @property
    def vehicle_count(self) -> int:
        """How many of the case's bodies are vehicles (the others, after them, are fixed objects)."""
        return len(self.vehicle_names) - len(self.fixed)

    @property
    def struck_object(self):
        """The fixed object of the first exchange (its vehicle 2), or None where that is a vehicle."""
        k = self.between[1] - self.vehicle_count
        return self.fixed[k] if k >= 0 else None

    @property
    def pole(self) -> bool:
        """The first exchange strikes a pole: automatic contact meets it as a disc (``model.contact.pole``), not a
        box."""
        return self.struck_object is not None and self.struck_object.kind == "pole"

    def body_path(self, b: int) -> str:
        """How results name body ``b``: "vehicles[i]" for a vehicle, "fixed[k]" for a fixed object."""
        n = self.vehicle_count
        return f"vehicles[{b}]" if b < n else f"fixed[{b - n}]"

    def body_entry(self, b: int):
        """How a case file and the JSON name body ``b`` in a pair ("between"): a vehicle by its index, a fixed
        object as "fixed[k]"."""
        return b if b < self.vehicle_count else self.body_path(b)

def as_arrays(inputs: CaseInputs, dtype=None) -> CaseInputs:
    """Every leaf as a jnp array (of ``dtype``, default: JAX's default float)."""
    dtype = dtype or jnp.result_type(float)
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=dtype), inputs)

def to_pytrees(inputs: CaseInputs, between=(0, 1)):
    """(Vehicle, State, Vehicle, State, Contact) of the bodies ``between`` (static: their indices in
    ``inputs.vehicles``) from CaseInputs. Pure and differentiable.

    A velocity or normal made from a non-finite speed, course, velocity_z or angle is NaN, so that
    the exchange gives the row its status; it is computed from stand-ins (the double-where), so that
    the row's zero cotangent times an infinite derivative cannot make NaN the gradient of a parameter
    it shares with other rows."""
    out = []
    for b in between:
        v = inputs.vehicles[b]
        out += [Vehicle(v.mass, v.inertia, v.length, v.width, v.height, v.cg_to_front, v.cg_height), _state(v)]
    c = inputs.contact
    ok, (azimuth, pitch) = _finite_stand_ins(c.normal, c.normal_pitch)
    contact = Contact(c.point, jnp.where(ok, normal_from_angles(azimuth, pitch), jnp.nan), c.restitution,
                      c.friction, c.penetration_time)
    return (*out, contact)

def body_states(inputs: CaseInputs) -> tuple:
    """Every body's ``State`` at the case start, in the order of ``inputs.vehicles``."""
    return tuple(_state(v) for v in inputs.vehicles)


def _state(v: VehicleInputs) -> State:
    ok, (speed, course, vz) = _finite_stand_ins(v.speed, v.course, v.velocity_z)
    sin, cos = la.sincos(course)
    velocity = jnp.where(ok, jnp.stack([speed * cos, speed * sin, vz * jnp.ones_like(speed)]), jnp.nan)
    return State(v.position, velocity, v.yaw, v.pitch, v.roll, v.angular_velocity)


def _finite_stand_ins(*xs):
    """(ok, xs with 0 for each where ok is False): ok where all of ``xs`` are finite."""
    ok = functools.reduce(operator.and_, [jnp.isfinite(x) for x in xs])
    return ok, tuple(jnp.where(ok, x, jnp.zeros_like(x)) for x in xs)
