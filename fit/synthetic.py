"""Synthetic oblique side impacts, for checking a reconstruction against known truth.

``oblique_case(rng)`` draws a case dict (vehicle 2's front into vehicle 1's right side; SI, angles
in degrees, rates in deg/s); ``UNKNOWNS`` are the six inputs a check recovers and ``EVIDENCE`` the
ten outputs it fits, each with its standard deviation. benchmarks/bench_fit.py and
tests/fit/test_reconstruction.py draw their cases from here.
"""

from __future__ import annotations

import math

UNKNOWNS = ["vehicles[0].speed", "vehicles[1].speed", "contact.restitution", "contact.friction",
            "contact.point[0]", "contact.point[1]"]
EVIDENCE = [("vehicles[0].delta_v_body[0]", 0.2), ("vehicles[0].delta_v_body[1]", 0.2),
            ("vehicles[1].delta_v_body[0]", 0.2), ("vehicles[1].delta_v_body[1]", 0.2),
            ("vehicles[0].yaw_rate_after", 0.02), ("vehicles[1].yaw_rate_after", 0.02),
            ("vehicles[0].speed_after", 0.2), ("vehicles[1].speed_after", 0.2),
            ("vehicles[0].crush", 0.03), ("vehicles[1].crush", 0.03)]


def oblique_case(rng) -> dict:
    """One random oblique side impact as a case dict (``ks_jax.case.case_from_dict``).
    ``rng``: a ``numpy.random.Generator``."""
    L1, L2 = rng.uniform(4.4, 5.0, 2)
    m1, m2 = rng.uniform(1200, 2200, 2)
    yaw2 = rng.uniform(60, 120)
    x_front = rng.uniform(-1.0, 1.2)
    cf2 = 0.5 * L2
    y_front = -0.9 + 0.35  # vehicle 2's front face 0.35 m into vehicle 1's right side
    c2 = [x_front - cf2 * math.cos(math.radians(yaw2)), y_front - cf2 * math.sin(math.radians(yaw2))]
    return {"name": "oblique", "vehicles": [
        {"mass": m1, "inertia": [500, 2200, 1.6 * m1], "length": L1, "width": 1.85, "height": 1.45,
         "cg_to_front": 0.45 * L1, "cg_height": 0.55, "position": [0, 0], "yaw": 0,
         "speed": rng.uniform(8, 20), "yaw_rate": rng.uniform(-10, 10)},
        {"mass": m2, "inertia": [500, 2200, 1.6 * m2], "length": L2, "width": 1.8, "height": 1.5,
         "cg_to_front": cf2, "cg_height": 0.55, "position": c2, "yaw": yaw2,
         "speed": rng.uniform(8, 20), "yaw_rate": rng.uniform(-10, 10)}],
        "contact": {"point": [x_front + rng.uniform(-0.3, 0.3), -0.65, 0.55], "normal": 90 + rng.uniform(-15, 15),
                    "restitution": rng.uniform(0.05, 0.3), "friction": rng.uniform(0.1, 0.35)}}
