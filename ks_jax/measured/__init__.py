"""Measured crash tests: NHTSA EV5 tests read, and a vehicle's delta-V from its accelerometers with its
uncertainty, as fit evidence (docs/measured.md).

Public API:

- ``read_test`` (an EV5 file -> ``CrashTest`` with its ``TestVehicle`` and ``Channel`` records), ``read_channel``
  (a channel's time and SI values);
- ``cfc_filter`` (the SAE J211/1 channel frequency class filter), ``cfc_coefficients``;
- ``measured_delta_v`` (-> ``MeasuredDeltaV``, with ``.evidence(index)`` for ``fit``), ``barrier_rebound``
  (-> ``Rebound``: a barrier test's rebound velocity and restitution), ``Uncertainty`` (the parts of a sigma).

NumPy only: nothing here needs JAX.
"""

from .ev5 import Channel, CrashTest, TestVehicle, read_channel, read_test
from .pulse import (MeasuredDeltaV, Rebound, Uncertainty, barrier_rebound, cfc_coefficients, cfc_filter,
                    measured_delta_v)

__all__ = ["Channel", "CrashTest", "MeasuredDeltaV", "Rebound", "TestVehicle", "Uncertainty", "barrier_rebound",
           "cfc_coefficients", "cfc_filter", "measured_delta_v", "read_channel", "read_test"]
