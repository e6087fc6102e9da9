"""A case's states at given times (``case.Motion.times``, the result's ``at``): before the impact from a vehicle's
approach, at the impact its state there, after it from the watched motion, against closed forms (docs/model.md,
"The approach")."""

import dataclasses

import numpy as np
import pytest

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
