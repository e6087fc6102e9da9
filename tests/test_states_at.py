"""A case's states at given times (``case.Motion.times``, the result's ``at``): before the impact from a vehicle's
approach, at the impact its state there, after it from the watched motion, against closed forms (docs/model.md,
"The approach")."""

import dataclasses

import numpy as np
import pytest

import fit
import ks_jax
from ks_jax.case import case_from_dict
from ks_jax.units import G0
from test_articulated import CAR, TRACTOR, TRAILER, rear_strike


@pytest.mark.slow
def test_states_before_at_and_after_the_impact_are_the_closed_forms():
    """The car of the coupled rear strike (a road of friction 0, 3 s) skids 10 m on a surface of friction 0.7 before
    striking the trailer at 15 m/s: at -0.5 s, within the skid, its speed is v + mu g 0.5; at 0 it is v; at 1 s it
    moves back at its velocity after the exchange, (v - J / m1), from where it struck; at 5 s, after the motion's
    3 s, it is where the motion ended. The trailer at 2 s has moved with the tractor at J / (m2 + m3); before the
    impact it has no approach (NaN)."""
    e, v, mu, skid = 0.3, 15.0, 0.7, 10.0
    raw = rear_strike(e, v, limit=3.0)
    raw["vehicles"][0]["approach"] = [{"wheels": "locked", "distance": f"{skid} m", "friction": mu}]
    case = case_from_dict(raw)
    times = ((-0.5, 0.0, 1.0, 5.0), (-1.0, 2.0), ())
    case = dataclasses.replace(case, motion=dataclasses.replace(case.motion, times=times))
    at = ks_jax.solve(case).result.at
    j = (1 + e) * CAR * TRAILER / (CAR + TRAILER) * v
    car_x = float(raw["vehicles"][0]["position"][0].split()[0])
    trailer_x = float(raw["vehicles"][1]["position"][0].split()[0])
    np.testing.assert_allclose(at[0].time, times[0])
    np.testing.assert_allclose(at[0].speed, [v + mu * G0 * 0.5, v, j / CAR - v, j / CAR - v], rtol=1e-6)
    after = v - j / CAR
    np.testing.assert_allclose(at[0].position[2:, 0], [car_x + after * 1.0, car_x + after * 3.0], atol=1e-8)
    assert at[0].position[1, 0] == pytest.approx(car_x, abs=1e-12)
    # within the skid, 0.5 s before the impact: v t + mu g t^2 / 2 behind it (interpolated within its step)
    assert at[0].position[0, 0] == pytest.approx(car_x - (v * 0.5 + 0.5 * mu * G0 * 0.25), abs=1e-4)
    assert np.isnan(at[1].speed[0])
    assert at[1].position[1, 0] == pytest.approx(trailer_x + 2.0 * j / (TRAILER + TRACTOR), abs=1e-8)
    assert at[2] is None


def edr_case(v=14.0):
    """A car that rolls freely, then locks its wheels over a 12 m skid into a parked car at ``v`` (a road of friction
    0.7): its event data recorder's pre-crash speeds, every 0.5 s from 5 s before the impact."""
    car = {"name": "car", "mass": "1500 kg", "inertia": ["540 kg*m^2", "2430 kg*m^2", "2700 kg*m^2"],
           "length": "4.5 m", "width": "1.8 m", "height": "1.4 m", "cg_to_front": "2.25 m", "cg_height": "0.55 m",
           "wheelbase": "2.7 m", "track": "1.55 m", "cg_to_front_axle": "1.2 m", "position": ["0 m", "0 m"],
           "yaw": 0, "speed": f"{v} m/s", "after": {"wheels": "locked"},
           "approach": [{"wheels": "free", "duration": "4 s"}, {"wheels": "locked", "distance": "12 m"}]}
    parked = dict(car, name="parked", position=["4.5 m", "0 m"], speed="0 m/s", approach=None)
    del parked["approach"]
    return {"name": "EDR", "vehicles": [car, parked], "contact": {"point": ["2.25 m", "0 m", "0.5 m"], "normal": 180,
            "restitution": 0.1, "friction": 0.3}, "road": {"friction": 0.7, "time_limit": "2 s"}}


EDR_TIMES = [-5.0 + 0.5 * k for k in range(10)]


@pytest.mark.slow
def test_a_fit_from_an_event_data_recorders_pre_crash_table_alone_recovers_the_impact_speed():
    """The car's pre-crash speeds at -5, -4.5, .. -0.5 s (noise-free, from a sweep of the case's impact speed over 12
    and 14 m/s with those outputs at a time: within the skid v + mu g |t|, before it v_skid + f g (|t| - t_skid),
    checked against those closed forms) as one evidence table; the impact speed unknown in [5, 40] m/s: the fit
    finds 14 m/s."""
    case = case_from_dict(edr_case())
    paths = [f"vehicles[0].speed@{t!r}" for t in EDR_TIMES]
    swept = ks_jax.sweep(case, {"vehicles[0].speed": [12.0, 14.0]}, outputs=paths)  # outputs at a time in a sweep
    speeds = [float(swept.outputs[p][1]) for p in paths]
    np.testing.assert_allclose(swept.outputs[paths[-1]], np.array([12.0, 14.0]) + 0.7 * G0 * 0.5, rtol=1e-6)
    skid_start = np.sqrt(14.0 ** 2 + 2 * 0.7 * G0 * 12.0)
    skid_time = (skid_start - 14.0) / (0.7 * G0)
    closed = [14.0 + 0.7 * G0 * -t if -t <= skid_time else skid_start + 0.015 * G0 * (-t - skid_time)
              for t in EDR_TIMES]
    np.testing.assert_allclose(speeds, closed, rtol=2e-3)  # within a step of the phase change, interpolated
    raw = edr_case(v=14.0)
    raw["unknowns"] = {"vehicles[0].speed": {"bounds": ["5 m/s", "40 m/s"], "start": "25 m/s"}}
    raw["evidence"] = [{"quantity": "vehicles[0].speed", "time": [f"{t} s" for t in EDR_TIMES],
                        "value": [f"{s} m/s" for s in speeds], "sigma": "0.5 m/s"}]
    result = fit.reconstruct(case_from_dict(raw), starts=2)
    assert result.estimate["vehicles[0].speed"] == pytest.approx(14.0, abs=1e-4)
    assert result.cost < 1e-6 and result.converged
