"""Numbers far from their usual scale: scenes far from the origin in float32, and the input to blame
for an overflow."""

from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np

from .. import units as U
from .errors import CaseWarning
from .inputs import CaseInputs
from .paths import parse_path
from .schema import INPUT_KINDS


FAR_IN_FLOAT32 = 1e3  # m: a scene this far from the origin loses precision in float32 (crush, EES)

def _computes_in_float32(dtype=None) -> bool:
    return jnp.dtype(dtype or jnp.result_type(float)) == jnp.float32

def _xy(x):
    return np.asarray(x, np.float64)[..., :2]

def scene_origin(inputs: CaseInputs, extra=(), dtype=None):
    """Where ``solve`` and ``sweep`` move the origin before computing: None where JAX computes in float64,
    or where no CG or impulse centroid lies more than FAR_IN_FLOAT32 from the origin; else the CGs'
    midpoint (x, y; the mean of every body's), float64, shape (..., 2) (0 for rows of a batch that are near the
    origin).

    Float32 (JAX's default) keeps about 7 digits: at survey coordinates (5e5 m) a position keeps only
    centimetres, and crush and EES come out far off. The exchange is the same in a translated scene
    (docs/model.md), so the scene is moved on the host in float64 (``move_scene``) and ``contact.point``
    moved back (``origin_offset``). ``extra``: more x, y values that the scene reaches (a sweep's positions).
    dtype: the compute dtype (default: JAX's default float)."""
    if not _computes_in_float32(dtype):
        return None
    cg = [_xy(v.position) for v in inputs.vehicles]
    reach = np.max([np.abs(c).max(-1) for c in cg], axis=0)
    reach = np.maximum(reach, np.abs(_xy(inputs.contact.point)).max(-1))
    reach = np.maximum(reach, max((np.abs(np.asarray(e, np.float64)).max() for e in extra), default=0.0))
    far = reach > FAR_IN_FLOAT32
    if not far.any():
        return None
    return np.where(far[..., None], sum(cg) / len(cg), 0.0)

def move_scene(inputs: CaseInputs, origin, auto_point=False) -> CaseInputs:
    """``inputs`` with the CG positions and the impulse centroid given about ``origin`` (x, y; float64,
    on the host): the same scene, translated (``scene_origin``). auto_point: the centroid is automatic
    (its input a placeholder, left as it is)."""
    def moved(x):
        x = np.array(x, np.float64)
        x[..., :2] -= origin
        return x

    point = inputs.contact.point if auto_point else moved(inputs.contact.point)
    return inputs._replace(vehicles=tuple(v._replace(position=moved(v.position)) for v in inputs.vehicles),
                           contact=inputs.contact._replace(point=point))

def xy_index(path: str):
    """0 or 1 where ``path`` is the x or y of a CG position or of the impulse centroid (an input, or
    the output contact.point[k], vehicles[i].rest_position[k] or vehicles[i].approach[j].position[k]), else None."""
    _, _, name, idx = parse_path(path)
    if name == "approach.position":
        return idx[1] if len(idx) == 2 and idx[1] in (0, 1) else None
    return idx[0] if name in ("position", "point", "rest_position") and idx[:1] in ((0,), (1,)) else None

def origin_offset(path: str, origin):
    """What ``move_scene`` subtracted from the input or output at ``path`` ("vehicles[0].position[0]",
    "contact.point[1]"): origin[..., k] for an x or y position or centroid, else None."""
    k = xy_index(path)
    return None if origin is None or k is None else origin[..., k]

def warn_far_from_origin(inputs: CaseInputs, extra=(), what="the scene", about="the origin", auto_point=False):
    """Warn (CaseWarning) where JAX computes in float32 (its default) and a CG, the impulse centroid (unless
    ``auto_point``) or an ``extra`` x, y value (a sweep's positions) lies more than FAR_IN_FLOAT32 from
    ``about`` even after ``move_scene``: vehicles kilometres apart, or a sweep of positions over kilometres."""
    if not _computes_in_float32():
        return
    xy = [np.abs(_xy(v.position)).max() for v in inputs.vehicles]
    if not auto_point:
        xy.append(np.abs(_xy(inputs.contact.point)).max())
    xy += [np.abs(np.asarray(e, np.float64)).max() for e in extra]
    far = max(xy)
    if far > FAR_IN_FLOAT32:
        warnings.warn(f"{what} reaches {far:.3g} m from {about} and JAX computes in float32 (its default): about 7 "
                      f"digits, so positions lose up to {far * 6e-8:.2g} m and crush and EES lose precision (0.5% "
                      "at 10 km). Enable float64 (jax.config.update('jax_enable_x64', True), as ks-jax's command "
                      "line does)", CaseWarning, stacklevel=3)

TYPICAL_SIZE = {"mass": 1500.0, "inertia": 2000.0, "length": 4.0, "velocity": 20.0, "angular_velocity": 1.0,
                "dimensionless": 1.0}

def farthest_out_of_scale(inputs: CaseInputs) -> str:
    """The input whose size is farthest from its kind's ``TYPICAL_SIZE`` (by the ratio, larger or smaller),
    as "vehicles[0].speed = 4.4704e+199 m/s": the one to name where a row's results overflow (status
    INVALID_OVERFLOW: the inputs are finite, the results are not). Zeros are left out."""
    worst, text = -1.0, ""
    for group, vi, holder in [("vehicles", i, v) for i, v in enumerate(inputs.vehicles)] + \
            [("contact", None, inputs.contact)]:
        for name, value in holder._asdict().items():
            kind = INPUT_KINDS.get(name)
            if kind not in TYPICAL_SIZE or name == "restitution":
                continue
            a = np.asarray(value, dtype=np.float64)
            size = np.abs(a)
            with np.errstate(divide="ignore"):
                far = np.where((size > 0) & np.isfinite(size), np.abs(np.log10(size / TYPICAL_SIZE[kind])), -1.0)
            k = np.unravel_index(int(np.argmax(far)), far.shape) if far.ndim else ()
            if far[k] > worst:
                where = f"vehicles[{vi}].{name}" if group == "vehicles" else f"contact.{name}"
                unit = U.SI_UNITS[kind]
                worst, text = float(far[k]), f"{where}{''.join(f'[{j}]' for j in k)} = {a[k]:.5g}" + \
                    (f" {unit}" if unit else "")
    return text
