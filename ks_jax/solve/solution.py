"""A solved case (``Solution``): its results, its status, the notes on what a user may not expect, and its JSON
(docs/model.md, "JSON output")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..case import Case, defined_output, undefined_kind
from ..model.types import ContactResult, ExchangeResult, VehicleResult


@dataclass
class Solution:
    """A solved case: ``result`` is an ExchangeResult of NumPy arrays (None for an invalid case)."""

    case: Case
    result: ExchangeResult | None
    status: str

    def notes(self) -> list:
        """Why a case gave what a user may not expect, in words (the panel prints them, ``--json`` lists them
        under "notes"). A vehicle still moving at the motion's time limit is named, with its speed then. A
        contact that is not closing at the centroid ("separating": no impulse) says the relative velocity
        there along the normal; where the case gives the normal, the reversed normal would be closing and the
        normal points from vehicle 1's CG's side towards vehicle 2's, it says that the normal may point the
        wrong way (docs/model.md: from vehicle 2 into vehicle 1, from a fixed object into the
        vehicle)."""
        if self.result is None or self.status.startswith("invalid"):
            return []
        notes = self._moving_notes()
        if self.status != "separating":
            return notes
        c = self.result.contact
        n, u = np.asarray(c.normal, float), np.asarray(c.closing_velocity, float)
        un = float(n @ u)
        notes.insert(0, f"no impulse: at the centroid the relative velocity along the normal is n . u = {un:.4g} m/s "
                     "(vehicle 1's velocity there minus vehicle 2's); an exchange needs it below 0 (closing)")
        x1, x2 = (np.asarray(v.position, float)[:2] for v in self.case.inputs.vehicles)
        # reversed it would be closing, and it points from vehicle 1's CG towards vehicle 2's (an object's
        # point): vehicles that are truly parting, under a normal that points the right way, get no such note
        if not self.case.auto_normal and un > 0 and float(n[:2] @ (x1 - x2)) < 0:
            names = self.case.vehicle_names
            into = (f"from the fixed {self.case.fixed.kind} into {names[0]}" if self.case.fixed is not None
                    else f"from vehicle 2 ({names[1]}) into vehicle 1 ({names[0]})")
            azimuth = round(math.degrees(math.atan2(-n[1], -n[0])) % 360.0, 1) % 360.0  # 359.97 is 0.0
            notes.append(f"the normal may point the wrong way: it must point {into}; reversed (azimuth "
                         f"{azimuth:.1f} deg) the vehicles would be closing at {un:.4g} m/s there")
        return notes

    def _moving_notes(self) -> list:
        rest = self.result.rest
        if rest is None:
            return []
        return [f"vehicles[{i}] ({self.case.vehicle_names[i]}) still moves at the time limit of the motion to rest "
                f"({self.case.motion.time_limit:g} s): its rest position, yaw, time and distance are where it is then; "
                "lengthen road.time_limit, or brake its wheels (after.wheels)"
                for i, r in enumerate(rest) if r is not None and not bool(r.at_rest)]

    def to_dict(self) -> dict:
        """{"name", "contact": {...}, "vehicles": [{...}, {...}]}: SI, the result names of docs/model.md,
        (against a fixed object: one vehicle, and "fixed": the object as the file gives it, SI, angles in rad;
        where ``notes`` has something to say, "notes": its list of sentences),
        the status in words, NaN as None: what ``ks-jax solve --json`` prints for the case. An invalid case
        has only its status. What the model leaves undefined is None too (``case.defined_output``): the
        impulse's directions where none was exchanged; the first-contact time, centroid, normal, closing
        and separation velocities and EES where the vehicles never touch; the course after of a vehicle at
        rest; and ``time`` at a given contact (it belongs to automatic contact)."""
        if self.result is None or self.status.startswith("invalid"):
            return {"name": self.case.name, "contact": {"status": self.status}, "vehicles": []}
        r = self.result
        contact = {k: _plain(defined_output(r, f"contact.{k}") if undefined_kind(f"contact.{k}")
                             else getattr(r.contact, k)) for k in ContactResult._fields if k != "status"}
        contact["status"] = self.status
        if not (self.case.auto_point or self.case.auto_normal):
            contact["time"] = None  # no search for a first contact: the exchange is at the case state
        vehicles = []
        fixed = self.case.fixed
        for i, (name, v) in enumerate(zip(self.case.vehicle_names, r.vehicles)):
            if i == 1 and fixed is not None:
                break  # a fixed object has no per-vehicle results
            d = {"name": name}
            d.update({k: _plain(defined_output(r, f"vehicles[{i}].{k}") if undefined_kind(f"vehicles[{i}].{k}")
                                else getattr(v, k)) for k in VehicleResult._fields})
            d["pdof_clock"] = None if d["pdof_clock"] is None else int(d["pdof_clock"])
            if r.rest is not None:
                d.update({k: _plain(x) for k, x in r.rest[i]._asdict().items() if k != "path"})
            vehicles.append(d)
        out = {"name": self.case.name, "contact": contact, "vehicles": vehicles}
        notes = self.notes()
        if notes:  # only where there is something to say: a case solved as expected has the keys of the model
            out["notes"] = notes
        if fixed is not None:
            out["fixed"] = {"name": self.case.vehicle_names[1],
                            **{k: _plain(v) for k, v in fixed._asdict().items() if v is not None and k != "kind"},
                            "kind": fixed.kind}
        return out


def _plain(x):
    """A result as plain JSON-ready data: a bool, a float (None for NaN), or a list of them; a vector that
    is undefined throughout is None, not a list of Nones."""
    x = np.asarray(x)
    if x.dtype == np.bool_:
        return bool(x) if x.ndim == 0 else [bool(v) for v in x]
    if x.ndim == 0:
        v = float(x)
        return None if not math.isfinite(v) else v
    if not np.isfinite(x).any():
        return None
    return [_plain(v) for v in x]
