"""Inverse reconstruction with ks_jax (docs/fit.md, `ks-jax fit`): ``import fit``.

``reconstruct(case, unknowns, evidence, ...)`` fits unknown inputs (speeds, restitution,
friction, the impulse centroid, any scalar input path) to measured results (delta-V, yaw rates,
speeds after, crush, PDOF, energy, EDR speeds: any scalar result path (docs/model.md, "Paths") or
a pre-impact speed), each with a sigma, by weighted least squares through the engine's
gradients (the smooth friction cone, ``smoothing`` > 0, keeps the loss differentiable).

Solver: a damped Gauss-Newton (Levenberg-Marquardt) step on the whitened residual vector,
with the Jacobian from ``jax.jacfwd`` (``fit.solvers``). With a handful of unknowns and a residual
vector, Gauss-Newton uses the curvature that the residuals give for free (J^T J), needs few
iterations, and its J at the optimum is the one the Laplace covariance needs anyway; it can afford
many starts. It was measured against optax's L-BFGS and Adam on the same problems
(``benchmarks/bench_fit.py --compare``; docs/performance.md), which stay available
(``solver="lbfgs"`` / ``"adam"``).

Multi-start: ``starts`` starts (the first at each unknown's ``start`` or the middle of its bounds,
the others a Latin hypercube within the bounds), vmapped in one compiled call, the best kept. Where fewer than
two starts reach the best fit, or its chi^2 is improbable, more rounds of starts follow (``max_starts``).
``reconstruct_batch`` fits many cases in one vmapped call (cases x starts). ``case_at(case, result.estimate)``
is the case at a fit's estimate, to solve and draw.

The package: ``spec`` (unknowns and evidence, read and checked), ``problem`` (what a fit compiles: the
residual vector), ``solvers`` (Levenberg-Marquardt, optax),
``rows`` (the compiled solver over cases x starts), ``starts``, ``rounds`` (more rounds of starts where a fit
needs them), ``reconstruction`` (``reconstruct`` and what a fit says), ``uncertainty``, ``monte_carlo``, ``report``
(the text report), ``synthetic`` (cases with known truth).

Uncertainty (``fit.uncertainty``): standard errors and correlations from the Gauss-Newton
(Laplace) covariance (J^T W J + prior)^-1 at the optimum, in the physical units (the delta
method through the bound transforms); optional Monte Carlo (evidence perturbed by its sigmas,
refitted by the same compiled solver, in calls of up to 500 rows on a CPU, 5/50/95 percentiles);
``unidentified``: what the evidence does not determine, from the small singular values of the
scaled Jacobian, in words, with std = inf (null in JSON) for those unknowns rather than a
confident number; ``at_bound``: unknowns pinned at a bound.
"""

from .problem import Problem, case_at
from .spec import Evidence, Unknown, parse_evidence, parse_unknowns
from .reconstruction import FitResult, reconstruct, reconstruct_batch

__all__ = ["Evidence", "FitResult", "Problem", "Unknown", "case_at", "parse_evidence", "parse_unknowns",
           "reconstruct", "reconstruct_batch"]
