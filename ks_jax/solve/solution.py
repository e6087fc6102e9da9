"""A solved case (``Solution``): its results, its status, the notes on what a user may not expect, and its JSON
(docs/model.md, "JSON output")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import numpy as np

from ..case import CUMULATIVE_OUTPUTS, Case, defined_output, undefined_kind
from ..model.pairs import pairs_of
from ..model.types import ContactResult, ExchangeResult, VehicleResult, status_text
from .crush import crush_results


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
        notes = self._moving_notes() + self._interaction_notes()
        if self.status != "separating":
            return notes
        c = self.result.contact
        n, u = np.asarray(c.normal, float), np.asarray(c.closing_velocity, float)
        un = float(n @ u)
        notes.insert(0, f"no impulse: at the centroid the relative velocity along the normal is n . u = {un:.4g} m/s "
                     "(vehicle 1's velocity there minus vehicle 2's); an exchange needs it below 0 (closing)")
        i, j = self.case.between
        x1, x2 = (np.asarray(self.case.inputs.vehicles[b].position, float)[:2] for b in (i, j))
        # reversed it would be closing, and it points from vehicle 1's CG towards vehicle 2's (an object's
        # point): vehicles that are truly parting, under a normal that points the right way, get no such note
        if not self.case.auto_normal and un > 0 and float(n[:2] @ (x1 - x2)) < 0:
            names, struck = self.case.vehicle_names, self.case.struck_object
            into = (f"from the fixed {struck.kind} into {names[i]}" if struck is not None
                    else f"from vehicle 2 ({names[j]}) into vehicle 1 ({names[i]})")
            azimuth = round(math.degrees(math.atan2(-n[1], -n[0])) % 360.0, 1) % 360.0  # 359.97 is 0.0
            notes.append(f"the normal may point the wrong way: it must point {into}; reversed (azimuth "
                         f"{azimuth:.1f} deg) the vehicles would be closing at {un:.4g} m/s there")
        return notes

    def _interaction_notes(self) -> list:
        """Where the watched motion left bodies inside each other: the exchanges stopped at ``max_exchanges`` while a
        pair was due for another, or footprints that overlap where the bodies end."""
        inter = self.result.interactions
        if inter is None:
            return []
        notes = []
        if bool(inter.exhausted):
            notes.append(f"the exchanges stopped at interaction.max_exchanges ({self.case.motion.max_exchanges}) while "
                         "a pair was due for another: from there the bodies may pass through each other unseen; "
                         "raise interaction.max_exchanges (up to 64)")
        names = self.body_names()
        n = self.case.vehicle_count
        links = tuple((towed, tow) for towed, tow, _ in self.case.motion.links)
        for (i, j), overlapping, depth in zip(pairs_of(n, len(names) - n, links),
                                              np.asarray(inter.overlapping), np.asarray(inter.overlap_depth)):
            if overlapping:
                notes.append(f"{_label(names[i])} and {_label(names[j])} overlap where they end, by {float(depth):.3g} "
                             "m (their undeformed outlines intersect): as much as they are crushed where they rest in "
                             "contact; more means one passed into the other")
        return notes

    def crush(self) -> list:
        """Each vehicle's crush-energy results from its measured crush profile (``crush.crush_results``): a dict per
        vehicle, its values None where it has no profile."""
        return crush_results(self.case)

    def body_names(self) -> list:
        """Each body as results name it: (path, name): "vehicles[i]" for a vehicle, "fixed[k]" for a fixed object."""
        return [(self.case.body_path(b), name) for b, name in enumerate(self.case.vehicle_names)]

    def exchange_list(self) -> list:
        """Every exchange of the case in time order as plain data (SI): the first is ``contact``; a case with a road
        adds those of the watched motion (docs/model.md, "Contact interactions"). Each: "time" (s from the first
        exchange), "between" ([i, j] vehicle indices, or [i, "fixed[k]"]), "interaction", the contact results and,
        for each vehicle of the pair, its delta-V, PDOF and share of the energy loss (Burg: in proportion to crush;
        all of it where the other is a fixed object; None where both crushes are 0)."""
        if self.result is None or self.status.startswith("invalid"):
            return []
        r, inter = self.result, self.result.interactions
        n = self.case.vehicle_count
        count = 1 if inter is None else int(inter.count)
        out = []
        for k in range(count):
            if inter is None:  # the one exchange, its vehicles' results in the order of the bodies
                pair = self.case.between
                ex = r._replace(vehicles=tuple(r.vehicles[b] for b in pair))
            else:
                ex = jax.tree_util.tree_map(lambda x: x[k], inter.exchanges)
                pair = tuple(int(b) for b in inter.between[k])
            contact = {f: _plain(defined_output(ex, f"contact.{f}") if undefined_kind(f"contact.{f}")
                                 else getattr(ex.contact, f)) for f in ContactResult._fields if f != "status"}
            contact["time"] = 0.0 if inter is None else _plain(inter.time[k])
            contact["status"] = status_text(ex.contact.status) if k else self.status
            crush = self._share_weights(k, pair, [float(v.crush) for v in ex.vehicles])
            energy = float(ex.contact.energy_loss)
            vehicles = []
            for side, b in enumerate(pair):
                if b >= n:
                    continue
                v = ex.vehicles[side]
                share = energy if pair[1 - side] >= n else (
                    energy * crush[side] / sum(crush) if sum(crush) > 0 else math.nan)
                vehicles.append({"vehicle": b, "delta_v": _plain(v.delta_v),
                                 "delta_v_magnitude": _plain(v.delta_v_magnitude),
                                 "pdof": _plain(defined_output(ex, f"vehicles[{side}].pdof")),
                                 "energy_share": _plain(share), "velocity_after": _plain(v.velocity_after)})
            between = [self.case.body_entry(b) for b in pair]
            out.append({"index": k, "between": between,
                        "interaction": 0 if inter is None else int(inter.interaction[k]), **contact,
                        "vehicles": vehicles})
        return out

    def split_by_crush_energy(self) -> bool:
        """Whether the first exchange's energy loss is shared by crush energy (both its bodies have a crush profile:
        ``pipeline.split_by_crush``), not by the box overlap's crushes."""
        weights = self.case.inputs.crush_energy if self.case.inputs is not None else ()
        return bool(weights) and all(weights[b] is not None for b in self.case.between)

    def _share_weights(self, k, pair, crush):
        """What exchange ``k`` of the bodies ``pair`` shares its energy loss by: their crush energies for the first
        exchange where ``split_by_crush_energy``, else the box overlap's ``crush``."""
        if k == 0 and self.split_by_crush_energy():
            return [float(self.case.inputs.crush_energy[b]) for b in pair]
        return crush

    def interactions_of(self, vehicle: int, exchanges: list) -> list:
        """The contact interactions ``vehicle`` took part in (from ``exchange_list``): each with its exchanges'
        indices and its cumulative delta-V (the velocity after its last exchange minus before its first, tyre forces
        between included) and the sum of its impulses over the mass ("delta_v_impulses")."""
        found: dict[int, list] = {}
        for ex in exchanges:
            for v in ex["vehicles"]:
                if v["vehicle"] == vehicle and (ex["impulse_magnitude"] or 0.0) > 0:
                    found.setdefault(ex["interaction"], []).append((ex["index"], v))
        out = []
        for index, items in found.items():
            first, last = items[0][1], items[-1][1]
            after_last = np.asarray(last["velocity_after"], float)
            before_first = np.asarray(first["velocity_after"], float) - np.asarray(first["delta_v"], float)
            impulses = sum(np.asarray(v["delta_v"], float) for _, v in items)
            dv = after_last - before_first
            out.append({"interaction": index, "exchanges": [k for k, _ in items], "delta_v": _plain(dv),
                        "delta_v_magnitude": _plain(np.linalg.norm(dv)), "delta_v_impulses": _plain(impulses)})
        return self._joined(vehicle, out)

    def _hitch(self, vehicle: int) -> dict:
        """{"hitch": ...} for a towed vehicle (docs/model.md, "Articulated vehicles"): its tow's index, the kind, the
        two points (m) and ``max_angle`` (rad, None for none) as the case gives them, and ``articulation_at_rest``
        (deg in (-180, 180]: its rest yaw minus its tow's); {} for any other vehicle."""
        motion = self.case.motion
        for (towed, tow, kind), h in zip(() if motion is None else motion.links, self.case.inputs.hitches):
            if towed != vehicle:
                continue
            return {"hitch": {"to": tow, "kind": kind, "point": _plain(h.point), "point_on_tow": _plain(h.point_on_tow),
                              "max_angle": _plain(h.max_angle),
                              "articulation_at_rest": _plain(self.articulation_at_rest(towed))}}
        return {}

    def _approach(self, vehicle: int) -> dict:
        """{"approach": [...]} for a vehicle with an approach (docs/model.md, "The approach"): at the start of each
        phase, earliest first, its "speed" (m/s), "time" (s from the impact, <= 0), "position" ([x, y] m of the CG),
        "yaw" (deg in [0, 360)) and "distance" (m, the CG's path from there to the impact); {} for any other
        vehicle."""
        approach = self.result.approach
        if approach is None or vehicle >= len(approach) or approach[vehicle] is None:
            return {}
        a = approach[vehicle]
        return {"approach": [{"speed": _plain(a.speed[k]), "time": _plain(a.time[k]), "position": _plain(a.position[k]),
                              "yaw": _plain(a.yaw[k]), "distance": _plain(a.distance[k])}
                             for k in range(np.shape(a.time)[-1])]}

    def articulation_at_rest(self, vehicle: int) -> float:
        """A towed vehicle's articulation at rest, deg in (-180, 180]: its rest yaw minus its tow's; NaN for a vehicle
        no hitch tows."""
        motion, rest = self.case.motion, self.result.rest
        tows = [tow for towed, tow, _ in (() if motion is None else motion.links) if towed == vehicle]
        if not tows or rest is None:
            return math.nan
        turn = float(rest[vehicle].rest_yaw) - float(rest[tows[0]].rest_yaw)
        return -((-turn + 180.0) % 360.0 - 180.0)

    def _joined(self, vehicle: int, interactions: list) -> list:
        """A hitched vehicle's ``interactions`` with its first one as the watched motion worked it: the joints'
        impulses right after each exchange included (docs/model.md, "Articulated vehicles"), and listed with no
        exchanges of its own where only its hitch took part (a tractor whose trailer was struck)."""
        inter = self.result.interactions
        if inter is None or not any(vehicle in link[:2] for link in self.case.motion.links):
            return interactions
        first = int(inter.first_interaction[vehicle])
        if first < 0:
            return interactions
        dv, impulses = np.asarray(inter.delta_v_cumulative[vehicle]), np.asarray(inter.delta_v_impulses[vehicle])
        joined = {"delta_v": _plain(dv), "delta_v_magnitude": _plain(np.linalg.norm(dv)),
                  "delta_v_impulses": _plain(impulses)}
        for entry in interactions:
            if entry["interaction"] == first:
                entry.update(joined)
                return interactions
        return sorted(interactions + [{"interaction": first, "exchanges": [], **joined}],
                      key=lambda entry: entry["interaction"])

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
        (a vehicle's per case vehicle, in order, with its crush-energy results (``crush``: None where
        it has no crush profile) and its "approach" where it has one; with fixed objects,
        "fixed": each as the file gives it, SI, angles in rad, one object or a list as in the file; "between": the
        first exchange's bodies;
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
        exchanges = self.exchange_list()
        crush = self.crush()
        for i, (name, v) in enumerate(zip(self.case.vehicle_names[:self.case.vehicle_count], r.vehicles)):
            d = {"name": name}
            d.update({k: _plain(defined_output(r, f"vehicles[{i}].{k}") if undefined_kind(f"vehicles[{i}].{k}")
                                else getattr(v, k)) for k in VehicleResult._fields})
            d["pdof_clock"] = None if d["pdof_clock"] is None else int(d["pdof_clock"])
            if r.rest is not None:
                d.update({k: _plain(x) for k, x in r.rest[i]._asdict().items() if k != "path"})
            d.update({k: _plain(defined_output(r, f"vehicles[{i}].{k}")) for k in CUMULATIVE_OUTPUTS})
            d.update(crush[i])
            d["interactions"] = self.interactions_of(i, exchanges)
            d.update(self._hitch(i))
            d.update(self._approach(i))
            vehicles.append(d)
        out = {"name": self.case.name, "between": [self.case.body_entry(b) for b in self.case.between],
               "contact": contact, "vehicles": vehicles, "exchanges": exchanges,
               "energy_loss_total": _plain(defined_output(r, "energy_loss_total"))}
        notes = self.notes()
        if notes:  # only where there is something to say: a case solved as expected has the keys of the model
            out["notes"] = notes
        if fixed:  # as the file gives it: one object, or a list of them
            names = self.case.vehicle_names[self.case.vehicle_count:]
            listed = [{"name": name, **{k: _plain(v) for k, v in obj._asdict().items()
                                        if v is not None and k != "kind"}, "kind": obj.kind}
                      for name, obj in zip(names, fixed)]
            out["fixed"] = listed if isinstance(self.case.raw.get("fixed"), list) else listed[0]
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


def _label(body) -> str:
    """A body as a note names it: 'vehicles[0] (Honda Accord)' (the name exactly; the panel escapes it)."""
    path, name = body
    return f"{path} ({name})"
