"""Inputs and results as pytrees (docs/model.md, "Inputs" and "Results").

All fields are arrays in SI units; the kernel sees one collision (no batch axis), and a
batch is the same pytree with a leading axis on every leaf (``jax.vmap`` at the edge).
``Vehicle.create``, ``State.create`` and ``Contact.create`` accept the convenient forms
(principal moments, speed and course, 2D positions, a normal azimuth) and build the
canonical arrays.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import linalg as la

Array = jnp.ndarray


def _f(x):
    return jnp.asarray(x, dtype=jnp.result_type(float))


def _given(where, name, x, shapes, meaning):
    """``x`` as ``_f`` gives it, after checking that it is numbers of one of ``shapes``: a clear error naming the
    argument instead of one from deep inside (None, a string) or a result of another shape. ``create`` makes one
    row; a list where one number belongs would give that field a batch axis no other field has (a batch is
    ``jax.vmap`` of ``create``). Shapes only: a traced value (under jit, vmap or grad) is checked as any other."""
    if x is None or isinstance(x, (str, bytes, dict)):
        raise TypeError(f"{where}: {name} = {x!r}: give {meaning}")
    try:
        x = _f(x)
    except (TypeError, ValueError):
        raise TypeError(f"{where}: {name} = {x!r}: give {meaning}") from None
    if x.shape not in shapes:
        raise ValueError(f"{where}: {name} has shape {x.shape}: give {meaning} ({where} makes one row: for a batch, "
                         "jax.vmap it)")
    return x


def _one(where, name, x, unit=None):
    """``_given`` of one number, in ``unit`` (None: a pure number)."""
    return _given(where, name, x, ((),), "one number" + (f", in {unit}" if unit else ""))


class Vehicle(NamedTuple):
    """Constant properties of one vehicle.

    mass: () kg. inertia: (3,) principal moments (Ixx, Iyy, Izz) about the CG in the body
    frame, kg m^2, or a (3, 3) tensor in the body frame. length, width, height: () m, the
    bounding box. cg_to_front: () m from the CG to the front face. cg_height: () m above ground.
    The box in body coordinates is x in [cg_to_front - length, cg_to_front],
    y in [-width/2, width/2], z in [-cg_height, height - cg_height].
    """

    mass: Array
    inertia: Array
    length: Array
    width: Array
    height: Array
    cg_to_front: Array
    cg_height: Array

    @classmethod
    def create(cls, mass, inertia, length, width, height=1.4, cg_to_front=None, cg_height=0.55):
        """One vehicle from SI values: each argument one number, ``inertia`` (3,) or (3, 3) (a batch: ``jax.vmap``
        this); ``cg_to_front`` defaults to half the length."""
        where = "Vehicle.create"
        length = _one(where, "length", length, "m")
        cg_to_front = 0.5 * length if cg_to_front is None else cg_to_front
        inertia = _given(where, "inertia", inertia, ((3,), (3, 3)),
                         "the principal moments (Ixx, Iyy, Izz) or a (3, 3) tensor, in kg m^2")
        sizes = (("width", width), ("height", height), ("cg_to_front", cg_to_front), ("cg_height", cg_height))
        return cls(_one(where, "mass", mass, "kg"), inertia, length, *(_one(where, n, x, "m") for n, x in sizes))


class State(NamedTuple):
    """Motion of one vehicle at the start of the case, global frame.

    position: (3,) m, the CG. velocity: (3,) m/s of the CG. yaw, pitch, roll: () rad,
    R = Rz(yaw) Ry(pitch) Rx(roll). angular_velocity: (3,) rad/s, global frame.
    """

    position: Array
    velocity: Array
    yaw: Array
    pitch: Array
    roll: Array
    angular_velocity: Array

    @classmethod
    def create(
        cls,
        position,
        yaw=0.0,
        *,
        velocity=None,
        speed=None,
        course=None,
        yaw_rate=None,
        angular_velocity=None,
        pitch=0.0,
        roll=0.0,
        cg_height=None,
    ):
        """One vehicle's state from SI values (angles in rad, rates in rad/s); a batch: ``jax.vmap`` this.

        position: (2,) or (3,); a 2D position gets z = ``cg_height``, the vehicle's (docs/model.md,
        "Inputs"), which must then be given (a State does not know its vehicle).
        Either ``velocity`` ((2,) or (3,)) or ``speed`` with ``course`` (default: yaw). A speed is >= 0: backwards
        travel is the course turned by pi, and a negative speed is refused, as a case file refuses it (a traced
        speed, under jit, vmap or grad, has no value to check here; the exchange does not see a speed).
        Either ``yaw_rate`` (one number, about z) or ``angular_velocity`` (3,). Every other argument is one number.
        """
        where = "State.create"
        position = _given(where, "position", position, ((2,), (3,)), "(x, y, z) or (x, y), in m")
        if position.shape[-1] == 2:
            if cg_height is None:
                raise ValueError("State.create: position (x, y) has no z: give (x, y, z), or cg_height= (the "
                                 "vehicle's: z defaults to cg_height)")
            position = jnp.concatenate([position, _one(where, "cg_height", cg_height, "m")[None]])
        yaw = _one(where, "yaw", yaw, "rad")
        for given, other, this in ((velocity, speed, "speed"), (velocity, course, "course"),
                                   (angular_velocity, yaw_rate, "yaw_rate")):
            if given is not None and other is not None:
                name = "velocity" if this != "yaw_rate" else "angular_velocity"
                raise ValueError(f"State.create: give {name} or {this}, not both ({this} would be ignored)")
        if velocity is None:
            if speed is None:
                raise ValueError("State.create needs velocity or speed")
            speed = _one(where, "speed", speed, "m/s")
            if not isinstance(speed, jax.core.Tracer) and speed < 0:
                raise ValueError(f"State.create: speed = {float(speed)!r}: speed must be >= 0 (reverse the course for "
                                 f"backwards travel: speed={-float(speed)!r}, course="
                                 f"{'yaw + pi' if course is None else 'the course given + pi'})")
            course = yaw if course is None else _one(where, "course", course, "rad")
            sin, cos = la.sincos(course)
            velocity = jnp.stack([speed * cos, speed * sin, jnp.zeros_like(speed)])
        velocity = _given(where, "velocity", velocity, ((2,), (3,)), "(vx, vy, vz) or (vx, vy), in m/s")
        if velocity.shape[-1] == 2:
            velocity = jnp.concatenate([velocity, jnp.zeros_like(velocity[:1])])
        if angular_velocity is None:
            wz = _given(where, "yaw_rate", 0.0 if yaw_rate is None else yaw_rate, ((),),
                        "one number, the rate about z in rad/s; angular_velocity= takes (wx, wy, wz)")
            angular_velocity = jnp.stack([jnp.zeros_like(wz), jnp.zeros_like(wz), wz])
        angular_velocity = _given(where, "angular_velocity", angular_velocity, ((3,),), "(wx, wy, wz), in rad/s")
        return cls(position, velocity, yaw, _one(where, "pitch", pitch, "rad"), _one(where, "roll", roll, "rad"),
                   angular_velocity)


def normal_from_angles(azimuth, pitch=0.0):
    """Unit normal from its azimuth (rad, from +x, counter-clockwise) and pitch (rad, elevation)."""
    azimuth, pitch = _f(azimuth), _f(pitch)
    (sa, ca), (sp, cp) = la.sincos(azimuth), la.sincos(pitch)
    return jnp.stack([cp * ca, cp * sa, sp], -1)


class Contact(NamedTuple):
    """One impulse exchange's contact.

    point: (3,) m, the impulse centroid P, global. normal: (3,) n, pointing from vehicle 2
    into vehicle 1 (normalised inside the kernel). restitution: () eps in [-1, 1].
    friction: () mu >= 0. penetration_time: () s, used by automatic contact only.
    """

    point: Array
    normal: Array
    restitution: Array
    friction: Array
    penetration_time: Array

    @classmethod
    def create(cls, point, normal=None, restitution=0.0, friction=0.5, *, azimuth=None, normal_pitch=0.0,
               penetration_time=0.0):
        """One contact from SI values: give ``normal`` as a vector or ``azimuth`` (rad) and ``normal_pitch`` (rad);
        every other argument but ``point`` (3,) is one number (a batch: ``jax.vmap`` this)."""
        where = "Contact.create"
        if normal is not None and azimuth is not None:
            raise ValueError("Contact.create: give normal (a vector) or azimuth, not both (azimuth would be ignored)")
        if normal is None:
            if azimuth is None:
                raise ValueError("Contact.create needs normal or azimuth")
            normal = normal_from_angles(_one(where, "azimuth", azimuth, "rad"),
                                        _one(where, "normal_pitch", normal_pitch, "rad"))
        point = _given(where, "point", point, ((3,),), "(x, y, z), in m")
        normal = _given(where, "normal", normal, ((3,),), "a vector (nx, ny, nz), or azimuth=")
        return cls(point, normal, _one(where, "restitution", restitution), _one(where, "friction", friction),
                   _one(where, "penetration_time", penetration_time, "s"))


class ContactResult(NamedTuple):
    """Per-exchange results (docs/model.md, "Results"). Shapes are for one exchange.

    point (3,) m; normal (3,) unit; time () s (0 for an explicit contact: the exchange is at
    the case state); impulse (3,) N s on vehicle 1; impulse_magnitude, impulse_normal (n.J),
    impulse_tangential () N s; impulse_azimuth () deg in [0, 360); impulse_elevation () deg (both a
    stand-in 0 where no impulse was exchanged, impulse_magnitude 0: mask them, as ``ks_jax.case.defined_output``
    and ``ks-jax solve --json`` do);
    sliding () bool (|T_c| > mu N_c beyond rounding: a contact with no tangential part does not slide, at
    mu = 0 too); closing_velocity (3,) m/s, u at P before; separation_velocity (3,) m/s,
    u' at P after; energy_loss () J; status () int32 code (``ks_jax.status_text`` gives the words).
    """

    point: Array
    normal: Array
    time: Array
    impulse: Array
    impulse_magnitude: Array
    impulse_normal: Array
    impulse_tangential: Array
    impulse_azimuth: Array
    impulse_elevation: Array
    sliding: Array
    closing_velocity: Array
    separation_velocity: Array
    energy_loss: Array
    status: Array


class VehicleResult(NamedTuple):
    """Per-vehicle results (docs/model.md, "Results").

    delta_v (3,) m/s; delta_v_magnitude () m/s = |J|/m; delta_v_body (3,) m/s (longitudinal,
    lateral left +, vertical); delta_yaw_rate () rad/s; velocity_after (3,) m/s; speed_after ()
    m/s (|velocity_after|); course_after () deg in [0, 360); angular_velocity_after (3,) rad/s;
    yaw_rate_after () rad/s; pdof () deg in [0, 360) (SAE J224); pdof_clock () 1..12 (both a stand-in
    0 and 12, which would read as frontal, where no impulse was exchanged: the contact's impulse_magnitude
    is 0; mask them, as ``ks_jax.case.defined_output``, sweeps and ``ks-jax solve --json`` do);
    crush () m; ees () m/s (NaN when both crushes are 0 or the energy loss is negative beyond rounding:
    undefined; an energy loss of 0 to rounding gives 0).
    """

    delta_v: Array
    delta_v_magnitude: Array
    delta_v_body: Array
    delta_yaw_rate: Array
    velocity_after: Array
    speed_after: Array
    course_after: Array
    angular_velocity_after: Array
    yaw_rate_after: Array
    pdof: Array
    pdof_clock: Array
    crush: Array
    ees: Array


class ExchangeResult(NamedTuple):
    """``contact``: a ContactResult; ``vehicles``: a pair of VehicleResult (vehicle 1, vehicle 2); ``rest``: where a
    case's vehicles move on to rest, a pair of ``model.motion.RestResult`` (None for a fixed object), else None;
    ``interactions``: where they move on, the exchanges that follow the first (``model.interaction.Interactions``,
    its ``rest`` empty: it is ``rest`` here), else None; ``approach``: where a case's vehicles have an approach, one
    entry per body, a ``model.approach.ApproachResult`` or None (a body without one), else None; ``at``: where a
    case asks for states at given times (``case.Motion.times``), one entry per body, a ``model.approach.StateAt``
    (with its ``time``) or None, else None."""

    contact: ContactResult
    vehicles: tuple
    rest: tuple | None = None
    interactions: Any = None
    approach: tuple | None = None
    at: tuple | None = None


# Status codes carried per row inside jit (docs/model.md, "status").
OK = 0
SEPARATING = 1
NO_CONTACT = 2
INVALID_NONFINITE = 10
INVALID_MASS_1 = 11
INVALID_MASS_2 = 12
INVALID_INERTIA_1 = 13
INVALID_INERTIA_2 = 14
INVALID_BOX_1 = 15
INVALID_BOX_2 = 16
INVALID_RESTITUTION = 17
INVALID_FRICTION = 18
INVALID_NORMAL = 19
INVALID_PENETRATION_TIME = 20
INVALID_SPEED_1 = 21  # a case's speed (CaseInputs), not an exchange input: see ``ks_jax.solve.rules.speed_status``
INVALID_SPEED_2 = 22
INVALID_SMOOTHING = 23  # an array ``smoothing`` (a Python number is refused by a ValueError)
INVALID_OVERFLOW = 24  # finite inputs whose results are not (say a speed of 1e300 m/s)
INVALID_PARTED = 25  # automatic contact: the footprints touched, then parted before t_i + penetration_time
INVALID_MOTION = 26  # an input of the motion to rest breaks its rule (a swept or fitted one: a file is checked)

STATUS_TEXT = {
    OK: "ok",
    SEPARATING: "separating",
    NO_CONTACT: "no_contact",
    INVALID_NONFINITE: "invalid: an input is NaN or infinite",
    INVALID_MASS_1: "invalid: vehicles[0].mass must be positive",
    INVALID_MASS_2: "invalid: vehicles[1].mass must be positive",
    INVALID_INERTIA_1: "invalid: vehicles[0].inertia must be symmetric positive definite",
    INVALID_INERTIA_2: "invalid: vehicles[1].inertia must be symmetric positive definite",
    INVALID_BOX_1: ("invalid: vehicles[0] length, width and height must be positive, cg_to_front in "
                      "[0, length] and cg_height in [0, height]"),
    INVALID_BOX_2: ("invalid: vehicles[1] length, width and height must be positive, cg_to_front in "
                      "[0, length] and cg_height in [0, height]"),
    INVALID_RESTITUTION: "invalid: contact.restitution must be in [-1, 1]",
    INVALID_FRICTION: "invalid: contact.friction must be >= 0",
    INVALID_NORMAL: "invalid: contact.normal must be a non-zero vector",
    INVALID_PENETRATION_TIME: "invalid: contact.penetration_time must be >= 0",
    INVALID_SPEED_1: "invalid: vehicles[0].speed must be >= 0 (reverse the course for backwards travel)",
    INVALID_SPEED_2: "invalid: vehicles[1].speed must be >= 0 (reverse the course for backwards travel)",
    INVALID_SMOOTHING: "invalid: smoothing must be in [0, 1)",
    INVALID_PARTED: ("invalid: contact.penetration_time is too long: the footprints touched but no longer overlap "
                     "at the exchange (first contact + penetration_time); shorten it"),
    INVALID_MOTION: ("invalid: an input of the motion to rest breaks its rule: road.friction in [0, 10], each brake "
                     "fraction in [0, 1], 0 < cg_to_front_axle < wheelbase, track > 0, 0 <= rolling_resistance < "
                     "road.friction (or 0 on a road of friction 0)"),
    INVALID_OVERFLOW: ("invalid: the results overflow (an input is far out of scale, e.g. a speed of 1e200 m/s or a "
                       "mass of 1e-300 kg)"),
}


def status_text(code) -> str:
    """The words for one status code (an int, or an array of one code: shape ()). An array of codes is refused,
    naming its shape: the words of each are one call each (``[status_text(c) for c in codes.tolist()]``). A code is
    a whole number: 10.5 would read as 10, NaN failed in int()."""
    value = np.asarray(code)
    if value.ndim:
        raise TypeError(f"status_text takes one status code, got an array of shape {value.shape}: for the words of "
                        "each, [ks_jax.status_text(c) for c in codes.tolist()]")
    if value.dtype.kind not in "iuf" or not (np.isfinite(value) and value == np.floor(value)):
        raise ValueError(f"status_text: code = {code!r}: a status code is a whole number (a result's "
                         "contact.status)")
    return STATUS_TEXT.get(int(value), f"invalid: unknown status {int(value)}")
