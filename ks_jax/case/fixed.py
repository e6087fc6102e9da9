"""Fixed objects (docs/model.md, "Fixed objects"): a wall, a pole or a rigid barrier, given to the exchanges as a
body: a box at rest of infinite mass (``model.checks.is_fixed``: 1/m and
I^-1 are 0), whose footprint automatic contact reads as it reads a second vehicle's.

- barrier: its own box, from the ground up to ``height``.
- wall: a half-plane, given as a box whose face towards the road is the wall's face: through ``point``, the
  box behind it, ``WALL_REACH`` long each way along the face and as deep, so that no vehicle can reach its
  ends within the first-contact search (HORIZON seconds at ``WALL_SPEED``) from where the case puts it.
- pole: the square about its disc, which automatic contact meets as the disc itself (``Case.pole``,
  ``model.contact.pole``): first touch of the footprint with the circle, the overlap of footprint and disc, a radial
  normal.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..model.contact import HORIZON
from .inputs import VehicleInputs

KINDS = ("wall", "pole", "barrier")
OBJECT_HEIGHT = 10.0  # m: a wall's or pole's height (and a barrier's by default): above any vehicle
WALL_SPEED = 100.0  # m/s: the fastest a vehicle is taken to run along a wall within the search horizon
WALL_MARGIN = 50.0  # m


class FixedObject(NamedTuple):
    """What a case file says of its fixed object, SI: kind ("wall", "pole", "barrier"); for a wall, ``point``
    (2,) on its face and ``normal`` (rad, the azimuth of its normal, out of the wall towards the road); for a
    pole, ``position`` (2,) and ``diameter``; for a barrier, ``position`` (2,), ``yaw``, ``length``, ``width``,
    ``height``. Fields a kind does not use are None."""

    kind: str
    point: np.ndarray | None = None
    normal: float | None = None
    position: np.ndarray | None = None
    diameter: float | None = None
    yaw: float | None = None
    length: float | None = None
    width: float | None = None
    height: float | None = None


def object_inputs(obj: FixedObject, vehicles) -> VehicleInputs:
    """The fixed object as a body of the exchanges: a box at rest, of infinite mass (``vehicles``: the case's
    ``VehicleInputs``, whose positions decide how long a wall must be)."""
    if obj.kind == "barrier":
        xy, yaw, length, width, height = obj.position, obj.yaw, obj.length, obj.width, obj.height
        cg_to_front = 0.5 * length
    elif obj.kind == "pole":  # the square about the disc (automatic contact meets the disc: ``model.contact.pole``)
        xy, length, width, height = obj.position, obj.diameter, obj.diameter, OBJECT_HEIGHT
        yaw, cg_to_front = 0.0, 0.5 * obj.diameter
    else:  # wall: the box's rear face (body -x) is the wall's face, so the box is turned to face into the wall
        far = max(float(np.hypot(*(np.asarray(v.position[:2]) - obj.point))) for v in vehicles)
        reach = far + WALL_SPEED * HORIZON + WALL_MARGIN
        xy, yaw, length, width, height = obj.point, obj.normal + math.pi, 2.0 * reach, 2.0 * reach, OBJECT_HEIGHT
        cg_to_front = length  # the "CG" on the face: the box runs from the face into the wall
    return VehicleInputs(mass=math.inf, inertia=np.eye(3), length=length, width=width, height=height,
                         cg_to_front=cg_to_front, cg_height=0.0, position=np.array([xy[0], xy[1], 0.0]), yaw=yaw,
                         pitch=0.0, roll=0.0, speed=0.0, course=0.0, velocity_z=0.0, angular_velocity=np.zeros(3))


def describe(obj: FixedObject) -> str:
    """One line for panels and pictures, SI: 'wall through (1.000, 2.000) m, normal 180.0 deg'."""
    if obj.kind == "wall":
        return (f"wall through ({obj.point[0]:.3f}, {obj.point[1]:.3f}) m, normal {math.degrees(obj.normal) % 360:.1f} "
                "deg (out of the wall)")
    if obj.kind == "pole":
        return f"pole at ({obj.position[0]:.3f}, {obj.position[1]:.3f}) m, diameter {obj.diameter:.3f} m"
    return (f"barrier at ({obj.position[0]:.3f}, {obj.position[1]:.3f}) m, yaw {math.degrees(obj.yaw) % 360:.1f} deg, "
            f"{obj.length:.3f} x {obj.width:.3f} x {obj.height:.3f} m")
