"""Where a group of cases is solved: about its CGs' midpoint where, in float32, it lies far from the origin
(``case.scale.scene_origin``), with its positions moved back into the results in float64."""

from __future__ import annotations

import numpy as np

from ..case.scale import move_scene, scene_origin, warn_far_from_origin


def about_midpoint(stacked, auto_point):
    """(the stacked inputs of a group of cases, moved where they are solved; the origin they were moved by, or None
    where they are solved where they are), with a warning where they lie far from where they are solved."""
    origin = scene_origin(stacked)
    if origin is not None:
        stacked = move_scene(stacked, origin, auto_point)
    warn_far_from_origin(stacked, what="a case", about="the origin" if origin is None else "its CGs' midpoint",
                         auto_point=auto_point)
    return stacked, origin


def moved_back(res, origin):
    """The results ``res`` (NumPy) of a group solved about ``origin`` with its positions (the centroid, the rest
    positions, the approach's positions) moved back, in float64."""
    if origin is None:
        return res
    point = res.contact.point.astype(np.float64)
    point[:, :2] += origin
    res = res._replace(contact=res.contact._replace(point=point))
    if res.rest is not None:
        res = res._replace(rest=tuple(None if r is None else r._replace(
            rest_position=r.rest_position.astype(np.float64) + origin) for r in res.rest))
    if getattr(res, "approach", None) is not None:  # (rows, P, 2) about (rows, 2)
        res = res._replace(approach=tuple(None if a is None else a._replace(
            position=a.position.astype(np.float64) + origin[:, None, :]) for a in res.approach))
    return res
