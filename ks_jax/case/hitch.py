"""Articulated vehicles in case files (docs/model.md, "Articulated vehicles: the case file"): a towed vehicle's
``hitch`` entry read and checked, the case's links put in order, and a towed vehicle's position and velocity
followed from its tow's through the hitch (``model.joint.follow``): once when the case is read (``follow_vehicles``,
on the host: a file may leave them out, and where it gives them they must agree), and in every computation
(``follow_tows``: pure jnp, so that a sweep or a fit of the tow's speed carries its trailer).

A hitch is given on the towed vehicle, ``"hitch": {"to": i, "point": [x, y], "point_on_tow": [x, y], "max_angle":
"35 deg", "kind": "drawbar"}``; each vehicle is towed at most once and may tow others (a tractor, its semi-trailer, a
full trailer behind that).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..model import linalg as la
from ..model.joint import Hitch, follow
from .errors import CaseError
from .fields import check_keys, given, number, require, shown, vector, where
from .inputs import CaseInputs, HitchInputs, VehicleInputs
from .schema import HITCH_FIELDS, TEXT_FIELDS

KINDS = ("drawbar", "fifth_wheel")
FOLLOW_POSITION = 0.05  # m: a towed vehicle's given position may lie this far from where its hitch puts it
FOLLOW_VELOCITY = 0.05  # m/s: and its given velocity this far from the one its hitch gives it
FOLLOWED = ("position", "speed", "course")  # the inputs a towed vehicle's hitch sets (of its position, x and y)
MAX_ANGLE = 180.0  # deg: the largest max_angle
EXAMPLE = '{"to": 0, "point": ["6.5 m", "0 m"], "point_on_tow": ["-1.2 m", "0 m"]}'


class Tow(NamedTuple):
    """One hitch as a case file gives it: the ``towed`` vehicle's and its ``tow``'s indices, its ``kind`` and its
    ``hitch`` (``HitchInputs``, SI)."""

    towed: int
    tow: int
    kind: str
    hitch: HitchInputs


def read_hitches(vehicles: list, case_name) -> tuple:
    """(``Motion.links``, ``CaseInputs.hitches``) of a case's ``vehicles`` entries (the file's tables): every
    ``hitch`` entry read and checked, and the links ordered so that the link that tows a vehicle comes before those
    in which it tows another. ((), ()) for a case without hitches."""
    tows = [_read(v["hitch"], i, len(vehicles), case_name) for i, v in enumerate(vehicles)
            if isinstance(v, dict) and "hitch" in v]
    tows = _ordered(tows, case_name)
    return tuple((t.towed, t.tow, t.kind) for t in tows), tuple(t.hitch for t in tows)


def _read(entry, i, vehicles, case_name) -> Tow:
    path = f"vehicles[{i}].hitch"
    if isinstance(entry, list):
        raise CaseError(f"{where(case_name, path)} = {shown(entry)}: must be one table: a vehicle is towed by one "
                        f"vehicle at most (and may tow others through their own hitch), e.g. {EXAMPLE}")
    if not isinstance(entry, dict):
        raise CaseError(f"{where(case_name, path)} = {shown(entry)}: must be a table/object, e.g. {EXAMPLE}")
    check_keys(entry, set(HITCH_FIELDS) | TEXT_FIELDS, path, case_name)
    to = require(entry, "to", path, case_name)
    others = ", ".join(str(k) for k in range(vehicles) if k != i) or "none"
    if isinstance(to, int) and not isinstance(to, bool) and to == i:
        raise CaseError(f"{where(case_name, path + '.to')} = {to}: a vehicle cannot tow itself; name the vehicle "
                        f"that tows it by its index ({others})")
    if not (isinstance(to, int) and not isinstance(to, bool) and 0 <= to < vehicles):
        raise CaseError(f"{where(case_name, path + '.to')} = {shown(to)}: must be the index of another vehicle of "
                        f"the case, the one that tows it ({others}); a fixed object tows nothing")
    point = vector(require(entry, "point", path, case_name), "length", f"{path}.point", case_name, (2,))
    on_tow = vector(require(entry, "point_on_tow", path, case_name), "length", f"{path}.point_on_tow", case_name,
                    (2,))
    max_angle = math.inf
    if "max_angle" in entry:
        raw = entry["max_angle"]
        max_angle = number(raw, "angle", f"{path}.max_angle", case_name, orientation=False)
        if not 0 < max_angle <= math.radians(MAX_ANGLE) * (1 + 1e-12):
            raise CaseError(f"{where(case_name, path + '.max_angle')} = {given(raw, max_angle, 'angle')}: must be "
                            f"in (0, {MAX_ANGLE:g}] deg, the largest articulation either way (leave it out for none)")
    kind = entry.get("kind", "drawbar")
    if kind not in KINDS:
        raise CaseError(f"{where(case_name, path + '.kind')} = {shown(kind)}: must be \"drawbar\" (a vehicle on "
                        "its own wheels: a full trailer, a towed car) or \"fifth_wheel\" (a semi-trailer, its front "
                        "carried by its tow at the hitch)")
    return Tow(i, to, kind, HitchInputs(np.array(point, dtype=float), np.array(on_tow, dtype=float), max_angle))


def _ordered(tows, case_name) -> list:
    """``tows`` with each vehicle's own link before those in which it tows (by the number of hitches between it and
    the head of its chain, then by index); a loop of hitches refused."""
    tow_of = {t.towed: t.tow for t in tows}
    depth = {}
    for t in tows:
        chain, v = [], t.towed
        while v in tow_of and v not in chain:
            chain.append(v)
            v = tow_of[v]
        if v in chain:
            loop = chain[chain.index(v):]
            first = min(loop)
            loop = loop[loop.index(first):] + loop[:loop.index(first)] + [first]
            words = ", towed by ".join(f"vehicles[{k}]" for k in loop)
            raise CaseError(f"{where(case_name, f'vehicles[{first}].hitch.to')} = {tow_of[first]}: the hitches make "
                            f"a loop ({words}): a vehicle cannot tow, directly or through others, the vehicle that "
                            "tows it")
        depth[t.towed] = len(chain)
    return sorted(tows, key=lambda t: (depth[t.towed], t.towed))


def hitched(i, j, links):
    """The link ``(towed, tow, kind)`` that couples bodies ``i`` and ``j`` (either way), else None."""
    return next((link for link in links if {link[0], link[1]} == {i, j}), None)


def _pair_words(link) -> str:
    return f"vehicles[{link[0]}] is towed by vehicles[{link[1]}] (vehicles[{link[0]}].hitch)"


def need_road(d, links, case_name):
    """Refuse a case with a hitch and no ``road``."""
    if links and "road" not in d:
        raise CaseError(f"{where(case_name, 'road')}: missing field; a case with a hitch (vehicles[{links[0][0]}]"
                        ".hitch) needs a road: the joint acts in the motion after the first exchange (add \"road\": "
                        "{\"friction\": 0.7}; docs/model.md, \"Articulated vehicles\")")


def check_between(value, between, links, case_name):
    """Refuse a first exchange (``between``, as the file gives it: ``value``, None for the default) between a
    hitched pair."""
    link = hitched(*between, links)
    if link:
        named = "[0, 1] (the default)" if value is None else shown(value)
        raise CaseError(f"{where(case_name, 'between')} = {named}: {_pair_words(link)}: a hitched pair is not "
                        "watched for contact with each other, so its first exchange cannot be between them; name the "
                        "two bodies that strike first")


def check_pairs(entries, pairs, links, case_name):
    """Refuse a ``pairs`` entry (``entries``, the file's; ``pairs``, their ``Motion.pairs`` in the same order)
    that names a hitched pair."""
    for n, (i, j) in enumerate(pairs):
        link = hitched(i, j, links)
        if link:
            raise CaseError(f"{where(case_name, f'pairs[{n}].between')} = {shown(entries[n]['between'])}: "
                            f"{_pair_words(link)}: a hitched pair is not watched for contact with each other, so it "
                            "has no later exchanges to give values to")


def check_fifth_wheels(vehicles, links, hitches, case_name):
    """Refuse a semi-trailer (``fifth_wheel``) whose CG does not lie between its hitch and its axle group: its hitch
    must lie ahead of its CG (its axle group, ``cg_to_front_axle - wheelbase``, lies behind it by the rule of every
    vehicle's axles)."""
    for (t, _, kind), h in zip(links, hitches):
        if kind == "fifth_wheel" and not h.point[0] > 0:
            raw = vehicles[t]["hitch"]["point"]
            raise CaseError(f"{where(case_name, f'vehicles[{t}].hitch.point')} = {shown(raw)}: a semi-trailer's "
                            "hitch (kind \"fifth_wheel\") must lie ahead of its CG (point[0] > 0): its CG lies between "
                            "the hitch, where its tow carries it, and its axle group")


def follow_vehicles(vehicles, veh, links, hitches, case_name) -> tuple:
    """The case's ``VehicleInputs`` (``veh``; ``vehicles``: the file's tables) with every towed vehicle's position (x,
    y; its z kept) and speed and course those its hitch gives it from its tow's, in link order. Where the file gives
    them they must agree, within ``FOLLOW_POSITION`` and ``FOLLOW_VELOCITY``; an articulation beyond ``max_angle`` is
    refused."""
    veh = list(veh)
    for (t, w, _), h in zip(links, hitches):
        d, v, tow = vehicles[t], veh[t], veh[w]
        angle = math.remainder(float(v.yaw) - float(tow.yaw), 2 * math.pi)
        if abs(angle) > h.max_angle * (1 + 1e-12):
            raise CaseError(f"{where(case_name, f'vehicles[{t}].hitch.max_angle')} = "
                            f"{given(d['hitch']['max_angle'], h.max_angle, 'angle')}: the vehicles start at an "
                            f"articulation of {math.degrees(angle):.4g} deg (vehicles[{t}].yaw minus "
                            f"vehicles[{w}].yaw), beyond it")
        position, velocity = _follow(tow, v, h)
        if "position" in d:
            gap = math.hypot(*(np.asarray(v.position[:2], dtype=float) - position))
            if gap > FOLLOW_POSITION:
                raise CaseError(f"{where(case_name, f'vehicles[{t}].position')} = {shown(d['position'])} (x, y = "
                                f"{_pair(v.position[:2])} m): its hitch to vehicles[{w}] puts its CG at (x, y) = "
                                f"({_pair(position)}) m, {gap:.4g} m away; a towed vehicle's position follows its "
                                f"tow's (vehicles[{w}]'s position and yaw, and its own yaw): give it within "
                                f"{FOLLOW_POSITION:g} m of that, or leave it out")
        _check_velocity(d, v, velocity, t, w, case_name)
        speed = math.hypot(*velocity)
        course = math.atan2(velocity[1], velocity[0]) if speed > 0 else 0.0  # as follow_tows: 0 at rest
        xyz = np.array([position[0], position[1], float(v.position[2])])
        veh[t] = v._replace(position=xyz, speed=speed, course=course)
    return tuple(veh)


def _check_velocity(d, v: VehicleInputs, velocity, t, w, case_name):
    """Refuse a towed vehicle's given velocity (``velocity``, or ``speed`` with or without ``course``) that does not
    agree with the one its hitch gives it (``velocity``, (2,) m/s); with ``speed`` alone, its size."""
    if "velocity" not in d and "speed" not in d:
        return
    field = "velocity" if "velocity" in d else "speed"
    if field == "speed" and "course" not in d:
        gap = abs(float(v.speed) - math.hypot(*velocity))
        stated = f"{float(v.speed):.4g} m/s"
        follows = f"a speed of {math.hypot(*velocity):.4g} m/s"
    else:
        given_v = float(v.speed) * np.array([math.cos(float(v.course)), math.sin(float(v.course))])
        gap = math.hypot(*(given_v - velocity))
        stated = f"(vx, vy) = ({_pair(given_v)}) m/s" + (f", course {shown(d['course'])}" if field == "speed" else "")
        follows = f"(vx, vy) = ({_pair(velocity)}) m/s"
    if gap > FOLLOW_VELOCITY:
        raise CaseError(f"{where(case_name, f'vehicles[{t}].{field}')} = {shown(d[field])} ({stated}): its hitch "
                        f"to vehicles[{w}] gives it {follows}, {gap:.4g} m/s apart; a towed vehicle's velocity "
                        f"follows its tow's (vehicles[{w}]'s speed, course and yaw rate, and its own yaw and yaw "
                        f"rate): give it within {FOLLOW_VELOCITY:g} m/s of that, or leave {field} (and course) out")


def _pair(xy) -> str:
    return f"{float(xy[0]):.4g}, {float(xy[1]):.4g}"


def _follow(tow: VehicleInputs, v: VehicleInputs, h: HitchInputs):
    """``model.joint.follow`` of the file's numbers, as host arrays: ((2,) m, (2,) m/s)."""
    tow_velocity = float(tow.speed) * np.array([math.cos(float(tow.course)), math.sin(float(tow.course))])
    position, velocity = follow(np.asarray(tow.position[:2], dtype=float), float(tow.yaw), tow_velocity,
                                float(tow.angular_velocity[2]), float(v.yaw), float(v.angular_velocity[2]),
                                Hitch(*(np.asarray(x, dtype=float) for x in h)))
    return np.asarray(position, dtype=float), np.asarray(velocity, dtype=float)


def follow_tows(inputs: CaseInputs, links) -> CaseInputs:
    """``inputs`` (one row: unbatched leaves; ``jax.vmap`` it over rows) with every towed vehicle's position (x, y;
    its z kept), ``speed`` and ``course`` those that ``model.joint.follow`` gives it from its tow's ``position``,
    ``yaw``, ``speed``, ``course`` and yaw rate (``angular_velocity[2]``) and its own ``yaw`` and yaw rate, link by
    link in ``links``' order (static: ``Motion.links``; a chain's tow is followed before its trailer). The speed is
    ``linalg.safe_norm`` of the horizontal velocity and the course its ``linalg.safe_atan2`` (0 at rest), so that
    derivatives stay finite at speed 0. Pure jnp: jit, vmap, jacfwd and grad go through it. Without links,
    ``inputs`` itself."""
    if not links:
        return inputs
    vehicles = list(inputs.vehicles)
    for (t, w, _), h in zip(links, inputs.hitches):
        tow, v = vehicles[w], vehicles[t]
        sin, cos = la.sincos(jnp.asarray(tow.course))
        speed = jnp.asarray(tow.speed)
        tow_position, own_position = jnp.asarray(tow.position), jnp.asarray(v.position)
        position, velocity = follow(tow_position[:2], tow.yaw, jnp.stack([speed * cos, speed * sin]),
                                    jnp.asarray(tow.angular_velocity)[2], v.yaw, jnp.asarray(v.angular_velocity)[2],
                                    Hitch(*h))
        xyz = jnp.concatenate([position, own_position[2:].astype(position.dtype)])
        vehicles[t] = v._replace(position=xyz, speed=la.safe_norm(velocity),
                                 course=la.safe_atan2(velocity[1], velocity[0]))
    return inputs._replace(vehicles=tuple(vehicles))

