"""Solve cases: a case's inputs to the exchange's results (docs/model.md), for one case or for every
case of a file at once.

- ``pipeline``: ``solve_inputs``, the case as a pure function of its inputs (jit, vmap and differentiate it at
  the edge: ``ks_jax.sweep`` and ``fit`` do), and ``stages``, the case's pipeline of stages: for a given contact,
  the exchange's own three stages; for automatic contact, the input rules, the contact (first touch, overlap),
  and the exchange there; with a road, the last stage carries the vehicles on to rest (``rest``);
- ``rules``: the statuses beyond the exchange's own (a negative speed, the motion's inputs) and a case's
  status in words;
- ``cases``: ``solve``, the cases of a file grouped by their pipeline, each group in one compiled call, and
  ``motion_paths`` and ``trajectories``; ``origin``: where a group is solved (about its CGs' midpoint far from the
  origin in float32);
- ``solution``: ``Solution``, a solved case, its notes and its JSON.
"""

from .cases import motion_paths, solve, trajectories
from .pipeline import solve_inputs, stages
from .solution import Solution

__all__ = ["Solution", "motion_paths", "solve", "solve_inputs", "stages", "trajectories"]
