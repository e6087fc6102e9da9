"""The rules an exchange's inputs must keep (docs/model.md, "Inputs"), as a per-row status code.

Nothing here raises or branches in Python on array values: a batch with one bad row gives that
row its status code, and ``benign`` swaps its inputs for harmless stand-ins before any arithmetic,
so that no NaN or infinity from the bad row reaches the values or gradients of the others.
"""

from __future__ import annotations

import functools
import operator

import jax
import jax.numpy as jnp

from . import linalg as la
from .types import (
    INVALID_BOX_1,
    INVALID_BOX_2,
    INVALID_FRICTION,
    INVALID_INERTIA_1,
    INVALID_INERTIA_2,
    INVALID_MASS_1,
    INVALID_MASS_2,
    INVALID_NONFINITE,
    INVALID_NORMAL,
    INVALID_PENETRATION_TIME,
    INVALID_RESTITUTION,
    INVALID_SMOOTHING,
    OK,
    Contact,
    Vehicle,
)


def _components(x):
    """The scalar components of a (), (3,) or (3, 3) leaf."""
    x = jnp.asarray(x)
    if x.ndim == 0:
        return (x,)
    if x.ndim == 1:
        return la.vec(x)
    return tuple(c for row in la.mat(x) for c in row)


def _all(flags):
    return functools.reduce(operator.and_, flags)


def _inertia_ok(inertia):
    """Principal moments all positive, or a symmetric tensor with positive leading minors (Sylvester).
    Written element by element, without reductions over a few components per row, which XLA's CPU
    loops run several times slower than the same checks written out."""
    inertia = jnp.asarray(inertia)
    if inertia.ndim == 1:
        return _all([c > 0 for c in la.vec(inertia)])
    m = la.mat(inertia)
    scale = jnp.abs(m[0][0])
    for row in m:
        for c in row:
            scale = jnp.maximum(scale, jnp.abs(c))
    symmetric = _all([jnp.abs(m[i][j] - m[j][i]) <= 1e-6 * scale for i, j in ((0, 1), (0, 2), (1, 2))])
    minor1 = m[0][0]
    minor2 = m[0][0] * m[1][1] - m[0][1] * m[1][0]
    return symmetric & (minor1 > 0) & (minor2 > 0) & (la.det3(m) > 0)


def _box_ok(v):
    """The box has a positive size and holds the CG (a swept ``cg_to_front`` may move it out)."""
    return ((v.length > 0) & (v.width > 0) & (v.height > 0) & (v.cg_to_front >= 0) & (v.cg_to_front <= v.length)
            & (v.cg_height >= 0) & (v.cg_height <= v.height))


def is_fixed(vehicle):
    """() bool: the body is a fixed object (a wall, pole or barrier: docs/model.md, "Fixed objects"), given as a
    vehicle of infinite mass, whose 1/m and I^-1 are 0 in the exchange. Only vehicle 2 may be one."""
    return vehicle.mass == jnp.inf


def input_status(vehicle1, state1, vehicle2, state2, contact, smoothing=0.0):
    """() int32: ``OK``, or the code of the first rule the inputs break (``ks_jax.model.types``).

    Vehicle 2's mass may be +inf: a fixed object (``is_fixed``); its inertia is then not used, but must
    still be valid (the identity will do). ``smoothing`` is checked only where it is an array (a traced
    tau, one per row); a Python number is checked once, by the caller, and refused with a ValueError."""
    leaves = jax.tree_util.tree_leaves((vehicle1, state1, vehicle2._replace(mass=jnp.zeros_like(vehicle2.mass)),
                                        state2, contact))
    finite = _all([jnp.isfinite(c) for x in leaves for c in _components(x)]) & ~jnp.isnan(vehicle2.mass) \
        & (vehicle2.mass != -jnp.inf)
    checks = [
        (finite, INVALID_NONFINITE),
        (vehicle1.mass > 0, INVALID_MASS_1),
        (vehicle2.mass > 0, INVALID_MASS_2),
        (_inertia_ok(vehicle1.inertia), INVALID_INERTIA_1),
        (_inertia_ok(vehicle2.inertia), INVALID_INERTIA_2),
        (_box_ok(vehicle1), INVALID_BOX_1),
        (_box_ok(vehicle2), INVALID_BOX_2),
        ((contact.restitution >= -1) & (contact.restitution <= 1), INVALID_RESTITUTION),
        (contact.friction >= 0, INVALID_FRICTION),
        (la.dot(contact.normal, contact.normal) > 0, INVALID_NORMAL),
        (contact.penetration_time >= 0, INVALID_PENETRATION_TIME),
    ]
    if not isinstance(smoothing, (int, float)):
        checks.append(((smoothing >= 0) & (smoothing < 1), INVALID_SMOOTHING))  # NaN fails
    code = jnp.int32(OK)
    for ok, bad in reversed(checks):  # the first failing rule wins
        code = jnp.where(ok, code, jnp.int32(bad))
    # stored once per row: every later step reads the code (``benign`` keys every input on it), and XLA's
    # fusion would otherwise copy the checks above into each of hundreds of loops, in a program many
    # times the size to compile (on a GPU too: each kernel would read every input again)
    return la.materialize(code, everywhere=True)[0]


def check_smoothing(smoothing):
    """Raise ValueError for a Python number outside [0, 1) (an array is checked per row instead)."""
    if isinstance(smoothing, (int, float)) and not 0.0 <= smoothing < 1.0:
        raise ValueError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")


def benign(inputs, ok):
    """``inputs`` = (vehicle1, state1, vehicle2, state2, contact) with every leaf replaced by a harmless
    value where ``ok`` is False: no NaN can leak out of a bad row, into its values or into the
    gradients of inputs it shares with other rows."""
    vehicle1, state1, vehicle2, state2, contact = inputs

    # stand-ins of the inputs' dtypes (a float64 constant would promote float32 inputs under x64)
    def veh(v):
        inertia = jnp.ones_like(v.inertia) if v.inertia.ndim == 1 else jnp.eye(3, dtype=jnp.result_type(v.inertia))
        good = Vehicle(1.0, inertia, 4.0, 2.0, 1.5, 2.0, 0.5)
        return jax.tree_util.tree_map(lambda x, g: jnp.where(ok, x, g), v, good)

    def st(s):
        return jax.tree_util.tree_map(lambda x: jnp.where(ok, x, jnp.zeros_like(x)), s)

    normal = jnp.asarray(contact.normal)
    good_contact = Contact(jnp.zeros_like(contact.point), jnp.array([1.0, 0.0, 0.0], dtype=normal.dtype), 0.0, 0.0, 0.0)
    contact = jax.tree_util.tree_map(lambda x, g: jnp.where(ok, x, g), contact, good_contact)
    return veh(vehicle1), st(state1), veh(vehicle2), st(state2), contact
