"""Results the model leaves undefined in some solved rows, and why (docs/model.md, "Undefined results").

The exchange carries stand-in numbers there (a PDOF of 0 would read as a frontal impact) so that it
never returns NaN and its gradients stay finite; ``defined_output`` gives NaN in their place, as the
JSON of ``ks-jax solve`` writes null.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..model.types import NO_CONTACT
from .paths import check_result, get_output, output_leaf, parse_path


CIRCULAR_OUTPUTS = frozenset({"pdof", "impulse_azimuth", "course_after", "rest_yaw", "delta_v_cumulative_pdof",
                              "approach.yaw", "at.yaw"})

_IMPULSE_DIRECTIONS = ("pdof", "pdof_clock", "impulse_azimuth", "impulse_elevation")
_CONTACT_ONLY = ("time", "point", "normal", "closing_velocity", "separation_velocity")  # contact.*

UNDEFINED_REASONS = {
    "direction": "no impulse was exchanged (separating, no contact, restitution -1), or the vehicle took no part in "
                 "the exchange: it has no direction",
    "contact": "the vehicles never touch within the search horizon: there is no first contact, centroid, "
               "normal or relative velocity at one",
    "ees": "both crushes are 0 (the centroid lies inside neither box, or the vehicles never touch) or the "
           "energy loss is negative",
    "heading": "the vehicle is at rest after the exchange: it has no direction of travel",
    "cumulative": "the vehicle took part in no exchange: its cumulative delta-V has no direction",
    "slot": "the case had fewer exchanges: this one did not happen",
}
REST_RATIO = 1e-6  # a horizontal speed after below this fraction of (speed before + delta-V) is rounding: at rest

def undefined_kind(path: str) -> str | None:
    """Which ``UNDEFINED_REASONS`` can leave the result at ``path`` undefined in a solved row; None: never."""
    group, _, name, _ = parse_path(path)
    if name == "delta_v_cumulative_pdof":
        return "cumulative"
    if name in _IMPULSE_DIRECTIONS:
        return "direction"
    if group in ("contact", "exchanges") and name in _CONTACT_ONLY:
        return "contact"
    return "ees" if name == "ees" else "heading" if name == "course_after" else None

def impulse_exchanged(result):
    """Whether an impulse was exchanged (not separating, no contact, or eps = -1): where not, the
    directions of the impulse (``undefined_kind`` "direction") are undefined."""
    return result.contact.impulse_magnitude > 0

def at_rest_after(vehicle_result):
    """Whether the vehicle's horizontal speed after the exchange is rounding (below ``REST_RATIO`` of its
    horizontal speed before plus its delta-V): then ``course_after`` is undefined."""
    after = vehicle_result.velocity_after
    before = after - vehicle_result.delta_v
    xp = _namespace(after, vehicle_result.delta_v_magnitude)
    horizontal = lambda v: xp.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2)  # noqa: E731
    return horizontal(after) <= REST_RATIO * (horizontal(before) + vehicle_result.delta_v_magnitude)

def _namespace(*arrays):
    """jax.numpy where any of ``arrays`` is a JAX array (traced in a sweep), else NumPy: a solved case's
    results are NumPy arrays, and jax.numpy on them compiled a small program per operation for every report
    (0.13-0.2 s of ``ks-jax solve``)."""
    return jnp if any(isinstance(a, jax.Array) for a in arrays) else np

def defined_output(result, path: str):
    """``get_output``, NaN where the result is undefined though the row is solved (``undefined_kind``):
    a direction of the impulse (pdof, pdof_clock, impulse_azimuth, impulse_elevation) where none was
    exchanged; the first-contact time, centroid, normal, closing and separation velocities, and EES,
    where the vehicles never touch; the course after of a vehicle at rest (``at_rest_after``). The
    exchange carries stand-in numbers there (a PDOF of 0 would read as a frontal impact), so that it never
    returns NaN and its gradients stay finite; the JSON of ``ks-jax solve`` writes them null. EES is NaN
    already where both crushes are 0 or the energy loss is negative. ``path`` may name a whole vector
    ("contact.point")."""
    check_result(result, "defined_output")
    group, vi, name, idx = parse_path(path)
    x = get_output(result, path) if idx else output_leaf(result, path)
    kind = undefined_kind(path)
    if group == "exchanges" and vi > 0:
        # a later exchange: NaN where it did not happen (its slot unused); an impulse was exchanged where it did
        return x
    if kind == "direction":
        defined = impulse_exchanged(result)
        if group == "vehicles":  # and the vehicle took part in it (a body the exchange left as it was has none)
            defined = defined & (result.vehicles[vi].delta_v_magnitude > 0)
    elif kind == "cumulative":
        defined = get_output(result, f"vehicles[{vi}].delta_v_cumulative_magnitude") > 0
    elif kind in ("contact", "ees"):
        defined = result.contact.status != NO_CONTACT
    elif kind == "heading":
        defined = ~at_rest_after(result.vehicles[vi])
    else:
        return x
    xp = _namespace(x, defined)
    defined = xp.reshape(defined, xp.shape(defined) + (1,) * (xp.ndim(x) - xp.ndim(defined)))
    return xp.where(defined, x, xp.nan)
