"""The arrays a fit works on, as one typed record (``FitArrays``): a batch's (B, ...) or one case's, built from
the cases and their parsed unknowns and evidence (``batch_arrays``, ``case_arrays``)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

from ks_jax.case import get_input
from ks_jax.case.scale import move_scene, origin_offset, scene_origin

from .host import collector_paused
from .rows import stack


class FitArrays(NamedTuple):
    """A fit's arrays, SI, float64: a batch's, each (B, n) per unknown or (B, m) per evidence, with ``inputs`` the
    cases' inputs stacked (``rows.stack``); or one case's (``row``), each (n,) or (m,), with ``inputs`` its own.

    values, sigmas: the evidence measured and its sigmas; lo, hi: the unknowns' bounds; pm: the priors' means (0
    where none); pw: 1 / the priors' sigmas (0 where none); the fit's coordinates, moved as ``inputs`` are (in
    float32 with a scene more than 1 km from the origin the scene is fitted about its CGs' midpoint:
    ``ks_jax.case.scale.scene_origin``). x_offset, e_offset: what was subtracted from each unknown and each piece
    of evidence, to move results back. current: the case's values of the unknowns; lower, upper, start,
    prior_mean, prior_sigma: the unknowns' own (NaN where none), unmoved, for the starts and the analysis."""

    values: np.ndarray
    sigmas: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    pm: np.ndarray
    pw: np.ndarray
    current: np.ndarray
    x_offset: np.ndarray
    e_offset: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    start: np.ndarray
    prior_mean: np.ndarray
    prior_sigma: np.ndarray
    inputs: object

    def take(self, cases) -> FitArrays:
        """The arrays of ``cases`` (indices) of a batch, inputs too."""
        return FitArrays(*(a[cases] for a in self[:-1]), jax.tree_util.tree_map(lambda v: v[cases], self.inputs))

    def row(self, i: int, inputs) -> FitArrays:
        """Case ``i``'s arrays of a batch, with ``inputs``: its own (not stacked) inputs."""
        return FitArrays(*(a[i] for a in self[:-1]), inputs)


@collector_paused()
def batch_arrays(cases, prepared, dtype) -> tuple[FitArrays, list]:
    """The ``FitArrays`` of a batch of cases (``prepared``: each case's unknowns and evidence, the same paths in
    each) fitted in ``dtype``, and the list of the cases' inputs, each moved about its CGs' midpoint where its
    scene is far from the origin in float32 (``FitArrays``)."""
    B = len(cases)
    paths = [u.path for u in prepared[0][0]]
    evidence_paths = [e.path for e in prepared[0][1]]
    n, m = len(paths), len(evidence_paths)
    nan = float("nan")
    own = np.array([[(u.lower, u.upper, nan if u.start is None else u.start, *(u.prior or (nan, nan))) for u in us]
                    for us, _, _ in prepared], np.float64).reshape(B, n, 5)
    measured = np.array([[(e.value, e.sigma) for e in es] for _, es, _ in prepared], np.float64).reshape(B, m, 2)
    x_offset, e_offset, inputs = np.zeros((B, n)), np.zeros((B, m)), []
    for i, case in enumerate(cases):
        origin = scene_origin(case.inputs, dtype=dtype)
        inputs.append(case.inputs if origin is None else move_scene(case.inputs, origin, case.auto_point))
        if origin is not None:
            x_offset[i] = [float(origin_offset(p, origin) or 0.0) for p in paths]
            e_offset[i] = [float(origin_offset(p, origin) or 0.0) for p in evidence_paths]
    stacked = stack(inputs)
    unmoved = stacked if all(a is c.inputs for a, c in zip(inputs, cases)) else stack([c.inputs for c in cases])
    current = np.stack([get_input(unmoved, p) for p in paths], axis=-1).reshape(B, n)
    lower, upper, start, prior_mean, prior_sigma = np.moveaxis(own, 2, 0)
    has_prior = ~np.isnan(prior_sigma)
    arrays = FitArrays(values=measured[..., 0] - e_offset, sigmas=measured[..., 1], lo=lower - x_offset,
                       hi=upper - x_offset, pm=np.where(has_prior, prior_mean, 0.0) - x_offset,
                       pw=np.where(has_prior, 1.0 / np.where(has_prior, prior_sigma, 1.0), 0.0), current=current,
                       x_offset=x_offset, e_offset=e_offset, lower=lower, upper=upper, start=start,
                       prior_mean=prior_mean, prior_sigma=prior_sigma, inputs=stacked)
    return arrays, inputs


def case_arrays(case, unknowns, evidence, dtype) -> FitArrays:
    """One case's ``FitArrays`` (``unknowns`` and ``evidence`` parsed, as a fit has them), with its own inputs."""
    arrays, inputs = batch_arrays([case], [(unknowns, evidence, None)], dtype)
    return arrays.row(0, inputs[0])
