"""Articulated vehicles (docs/model.md, "Articulated vehicles"): a trailer coupled to its tractor by a hitch, through
``ks-jax solve --json`` and the Python results, against closed forms: the in-line rear strike on a coupled trailer (the
exchange ignores the joint, the joint's plastic impulse then gives tractor and trailer one velocity), a coupled tow
braking to rest as one vehicle of the summed mass, the mass centre of a frictionless combination moving as its
momentum says, the hitch points together through a jack-knife, and gradients of rest positions against finite
differences.

The first three cases share one program (three vehicles, the trailer on the tractor's fifth wheel, a given contact, a
3 s time limit): the first test compiles it, the next two reuse it."""

import dataclasses
import json

import jax
import numpy as np
import pytest

import ks_jax
from ks_jax.case import case_from_dict
from ks_jax.model.joint import Hitch, articulation, hitch_gap
from ks_jax.model.motion import Planar
from ks_jax.units import G0
from samples import reference_jit, run_cli

CAR, TRAILER, TRACTOR = 1500.0, 10000.0, 8000.0  # kg
KINGPIN = [5.5, 0.0]  # m, the hitch in the trailer's frame: 0.5 m behind its front (its CG in the middle of 12 m)
FIFTH_WHEEL = [-1.5, 0.0]  # m, in the tractor's frame


def vehicle(name, mass, length, width, x, speed, izz, y=0.0, yaw=0.0, wheels="free", **more):
    """A box of ``length`` x ``width``, its CG in the middle, heading ``yaw`` at ``(x, y)``."""
    return {"name": name, "mass": f"{mass} kg", "inertia": [f"{izz / 5} kg*m^2", f"{izz} kg*m^2", f"{izz} kg*m^2"],
            "length": f"{length} m", "width": f"{width} m", "height": "2 m", "cg_to_front": f"{length / 2} m",
            "cg_height": "1 m", "wheelbase": f"{0.6 * length} m", "track": f"{0.85 * width} m",
            "cg_to_front_axle": f"{0.3 * length} m", "position": [f"{x} m", f"{y} m"], "yaw": yaw,
            "speed": f"{speed} m/s", "after": {"wheels": wheels, "rolling_resistance": 0}, **more}


def rear_strike(e=0.3, speed=15.0, y=0.0, friction=0.0, limit=3.0):
    """A car at ``speed`` into the rear of a trailer coupled to its tractor, both at rest, all in line along +x (the
    car ``y`` off the line), the exchange at the trailer's rear face; a road of ``friction`` (0: frictionless)."""
    tractor_x = 20.0
    trailer_x = tractor_x + FIFTH_WHEEL[0] - KINGPIN[0]
    face = trailer_x - 6.0
    return {"name": "car into a coupled trailer",
            "vehicles": [vehicle("car", CAR, 4.5, 1.8, face - 2.25, speed, 2500.0, y=y),
                         vehicle("trailer", TRAILER, 12.0, 2.5, trailer_x, 0.0, 120000.0,
                                 hitch={"to": 2, "point": [f"{x} m" for x in KINGPIN],
                                        "point_on_tow": [f"{x} m" for x in FIFTH_WHEEL], "kind": "fifth_wheel"}),
                         vehicle("tractor", TRACTOR, 6.0, 2.5, tractor_x, 0.0, 30000.0)],
            "contact": {"point": [f"{face} m", f"{y} m", "1 m"], "normal": 180, "restitution": e, "friction": 0.0},
            "road": {"friction": friction, "time_limit": f"{limit} s"}}


@pytest.mark.slow
def test_a_rear_strike_on_a_coupled_trailer_through_solve_json_is_the_closed_form(tmp_path, capsys):
    """In line, frictionless: the exchange is the one-dimensional impact of car and trailer, J = (1 + e) m1 m2 /
    (m1 + m2) v, ignoring the tractor; the joint's plastic impulse then leaves trailer and tractor at one velocity,
    J / (m2 + m3). The exchange's delta-V excludes the joint, the cumulative delta-V includes it, for the tractor
    too; momentum is conserved; and each vehicle then moves on at its velocity."""
    e, v, limit = 0.3, 15.0, 3.0
    path = tmp_path / "rear.json"
    path.write_text(json.dumps(rear_strike(e, v, limit=limit)))
    code, text, err = run_cli(capsys, "solve", str(path), "--json")
    assert code == 0, err
    (out,) = json.loads(text)["cases"]
    j = (1 + e) * CAR * TRAILER / (CAR + TRAILER) * v
    car, trailer, tractor = out["vehicles"]
    assert out["contact"]["impulse_magnitude"] == pytest.approx(j, rel=1e-12)
    np.testing.assert_allclose(car["delta_v"], [-j / CAR, 0, 0], atol=1e-9)
    np.testing.assert_allclose(trailer["delta_v"], [j / TRAILER, 0, 0], atol=1e-9)
    np.testing.assert_allclose(tractor["delta_v"], [0, 0, 0], atol=1e-12)
    common = j / (TRAILER + TRACTOR)
    np.testing.assert_allclose(car["delta_v_cumulative"], [-j / CAR, 0, 0], atol=1e-9)
    np.testing.assert_allclose(trailer["delta_v_cumulative"], [common, 0, 0], atol=1e-9)
    np.testing.assert_allclose(tractor["delta_v_cumulative"], [common, 0, 0], atol=1e-9)
    momentum = CAR * (v + np.array(car["delta_v_cumulative"])[0]) + (TRAILER + TRACTOR) * common
    assert momentum == pytest.approx(CAR * v, rel=1e-12)
    assert len(out["exchanges"]) == 1  # the car rebounds: no second exchange
    start = rear_strike(e, v)["vehicles"]
    for vehicle_out, raw, speed in zip(out["vehicles"], start, (v - j / CAR, common, common)):
        x0 = float(raw["position"][0].split()[0])
        np.testing.assert_allclose(vehicle_out["rest_position"], [x0 + speed * limit, 0.0], atol=1e-8)
    assert trailer["hitch"]["to"] == 2 and trailer["hitch"]["kind"] == "fifth_wheel"
    assert trailer["hitch"]["point"] == KINGPIN and trailer["hitch"]["max_angle"] is None
    assert trailer["hitch"]["articulation_at_rest"] == pytest.approx(0.0, abs=1e-9) and "hitch" not in tractor
    # the tractor's interaction is the trailer's: it took no part in the exchange, its joint did
    assert tractor["interactions"][0]["exchanges"] == []
    np.testing.assert_allclose(tractor["interactions"][0]["delta_v"], [common, 0, 0], atol=1e-9)


@pytest.mark.slow
def test_a_frictionless_combination_struck_off_centre_keeps_its_mass_centre_on_the_line_its_momentum_gives():
    """The car, turned 20 deg and 0.8 m off the line, strikes the trailer's rear with friction at the contact: the
    trailer swings about its hitch and drags the tractor. On a road of friction 0 with free wheels nothing outside
    acts on the three (the exchanges and the joint's impulses are internal), so their mass centre moves on at the
    car's momentum over the total mass: sum m x(T) = sum m x(0) + T m_car v. (The program of the rear strike above.)"""
    raw = rear_strike(e=0.2, speed=15.0, y=0.8, limit=3.0)
    raw["vehicles"][0]["yaw"] = 20
    raw["contact"]["friction"] = 0.4
    out = ks_jax.solve(case_from_dict(raw)).to_dict()
    masses = np.array([CAR, TRAILER, TRACTOR])
    start = np.array([[float(c.split()[0]) for c in v["position"]] for v in raw["vehicles"]])
    end = np.array([v["rest_position"] for v in out["vehicles"]])
    momentum = CAR * 15.0 * np.array([np.cos(np.radians(20)), np.sin(np.radians(20))])
    np.testing.assert_allclose(masses @ end, masses @ start + 3.0 * momentum, rtol=1e-9, atol=1e-6)
    assert abs(out["vehicles"][1]["rotation_to_rest"]) > 1.0  # the trailer did swing


def braking(kind="fifth_wheel", speed=20.0, friction=0.7, wheels=("locked", "locked"), steer=0.0, max_angle=None,
            limit=3.0):
    """A tractor and its semi-trailer at ``speed`` along +x on a road of ``friction``, the trailer's wheels and the
    tractor's as ``wheels`` (the tractor's front ones steered ``steer`` deg); a parked car far behind, whose exchange
    with the trailer (the case's first) parts them at once: no impulse."""
    hitch = {"to": 2, "point": ["5 m", "0 m"], "point_on_tow": ["-2.2 m", "0 m"], "kind": kind}
    if max_angle is not None:
        hitch["max_angle"] = f"{max_angle} deg"
    trailer = vehicle("trailer", 20000.0, 13.0, 2.5, -7.2, speed, 250000.0, wheels=wheels[0], hitch=hitch)
    trailer.update(wheelbase="10 m", cg_to_front_axle="5 m", cg_height="1.6 m")
    tractor = vehicle("tractor", 8000.0, 6.0, 2.5, 0.0, speed, 30000.0, wheels=wheels[1])
    tractor.update(wheelbase="3.8 m", cg_to_front_axle="1.2 m")
    tractor["after"]["steer"] = f"{steer} deg"
    return {"name": "a tractor and semi-trailer braking",
            "vehicles": [vehicle("parked car", CAR, 4.5, 1.8, -80.0, 0.0, 2500.0, wheels="locked"), trailer, tractor],
            "contact": {"point": ["-77 m", "0 m", "1 m"], "normal": 180, "restitution": 0.1, "friction": 0.3},
            "road": {"friction": friction, "time_limit": f"{limit} s"}}


@pytest.mark.slow
def test_a_straight_coupled_tow_brakes_to_rest_as_one_vehicle_of_the_summed_mass():
    """Every wheel of a tractor and its semi-trailer locked: on its own the tractor, carrying the trailer's front,
    would stop in a shorter distance than v^2 / (2 mu g), the trailer on its axle group alone in a longer one; coupled,
    the combination slides as one vehicle of the summed mass, d = v^2 / (2 mu g), t = v / (mu g) (to within a step
    of 5 ms)."""
    v, mu = 20.0, 0.7
    out = ks_jax.solve(case_from_dict(braking(speed=v, friction=mu))).to_dict()
    d, t = v * v / (2 * mu * G0), v / (mu * G0)
    parked, trailer, tractor = out["vehicles"]
    assert parked["distance_to_rest"] == 0.0 and out["exchanges"][0]["impulse_magnitude"] in (0.0, None)
    for vehicle_out, x0 in ((trailer, -7.2), (tractor, 0.0)):
        np.testing.assert_allclose(vehicle_out["rest_position"], [x0 + d, 0.0], rtol=0, atol=2e-3)
        assert vehicle_out["distance_to_rest"] == pytest.approx(d, abs=2e-3)
        assert vehicle_out["time_to_rest"] == pytest.approx(t, abs=0.011)
        assert vehicle_out["rest_yaw"] == pytest.approx(0.0, abs=1e-9)
    # the kingpin's share of the trailer's weight, (5 m) / (5 m + 5 m): the tractor alone would stop at
    # v^2 / (2 mu g (1 + share m_trailer / m_tractor))
    alone = v * v / (2 * mu * G0 * (1 + 0.5 * 20000.0 / 8000.0))
    assert alone < 0.5 * d


@pytest.mark.slow
def test_a_jack_knife_keeps_the_hitch_points_together_and_stops_at_the_articulation_limit():
    """The tractor's rear wheels locked, its front ones steered 3 deg, the trailer's free: the tractor spins about
    the hitch (a jack-knife) until the articulation reaches its limit of 80 deg, and the two turn on together. At
    every step of the path the hitch points lie within 1 mm of each other, and the articulation never exceeds its
    limit."""
    raw = braking(wheels=("free", [0, 0, 1, 1]), steer=3.0, max_angle=80.0, limit=8.0)
    case = case_from_dict(raw)
    kept = dataclasses.replace(case, motion=dataclasses.replace(case.motion, path=True))  # every step kept
    trailer, tractor = (np.asarray(r.path) for r in ks_jax.solve(kept).result.rest[1:])
    steps = len(trailer)
    hitch = Hitch(np.array([5.0, 0.0]), np.array([-2.2, 0.0]), np.radians(80.0))

    def planar(p):
        return Planar(p[1:3], p[3], np.zeros(2), 0.0)

    gaps = [float(np.linalg.norm(hitch_gap(planar(trailer[k]), planar(tractor[k]), hitch))) for k in range(steps)]
    angles = np.degrees([float(articulation(trailer[k, 3], tractor[k, 3])) for k in range(steps)])
    assert max(gaps) < 1e-3
    assert np.max(np.abs(angles)) <= 80.0 + 1e-6
    assert np.max(np.abs(angles)) > 79.9  # it did jack-knife to the limit


@pytest.mark.slow
def test_gradients_of_rest_positions_through_the_joint_match_finite_differences():
    """d (every vehicle's rest position) / d (the car's speed) in forward mode, compiled as fits compile it, through
    the off-centre strike on a road with friction, the joint's impulses and corrections at every step, against
    central differences of the same program's values. The car rolls back after the strike without rolling resistance,
    its yaw rate damped toward 0: its steps' changes fall far below rounding next to its velocity, where the energy
    rule's quotient once made the derivative NaN."""
    raw = rear_strike(e=0.2, speed=12.0, y=0.6, friction=0.6, limit=6.0)
    raw["contact"]["friction"] = 0.4
    case = case_from_dict(raw)

    def rests(speed):
        inputs = ks_jax.set_input(case.inputs, "vehicles[0].speed", speed)
        result = ks_jax.solve_inputs(inputs, motion=case.motion, between=case.between)
        return jax.numpy.concatenate([r.rest_position for r in result.rest])

    # one forward-mode pass gives the values and their derivative: the program holds the motion once, with tangents.
    # Compiled with the quick settings, as the fits compile theirs
    program = reference_jit(lambda s: jax.jvp(rests, (s,), (jax.numpy.ones_like(s),)))
    value, derivative = program(12.0)
    h = 1e-4
    central = (program(12.0 + h)[0] - program(12.0 - h)[0]) / (2 * h)
    assert np.all(np.isfinite(derivative)) and np.max(np.abs(derivative)) > 0.05
    np.testing.assert_allclose(derivative, central, rtol=2e-3, atol=2e-4)
