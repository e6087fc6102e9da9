"""ks-jax: the Kudlich-Slibar impulse-momentum collision model in JAX (docs/model.md).

Public API:

- the physics of one collision: ``exchange`` (pure, unbatched; jit, vmap and differentiate it), its
  inputs ``Vehicle``, ``State``, ``Contact`` and results ``ExchangeResult``, ``ContactResult``,
  ``VehicleResult``; ``status_text`` (a status code in words), ``normal_from_angles``;
- batches: ``exchange_batch`` (values into NumPy arrays), ``sum_over_rows`` (a batched loss whose
  gradient is computed chunk by chunk);
- case files: ``load_case``, ``load_cases``, ``Case``, ``CaseInputs``, ``CaseError``, and the paths of
  single inputs and results: ``get_input``, ``set_input``, ``get_output``;
- solving cases: ``solve`` (-> ``Solution``), ``solve_inputs`` (a case as a pure function of its inputs);
- sweeps: ``sweep`` (-> ``SweepResult``);
- ``keep_programs`` (keep compiled programs between processes), ``free_programs`` (free this process's
  compiled programs), ``units`` (conversions to SI).

Also: ``ks_jax.plot`` (pictures; matplotlib, the ``plot`` extra, is imported when a picture is drawn),
``ks_jax.report`` (the text panel), and ``fit`` (the reconstruction package installed beside ``ks_jax``).
"""

from . import plot, report, units
from .batch import exchange, exchange_batch, sum_over_rows
from .case import Case, CaseError, CaseInputs, get_input, get_output, load_case, load_cases, set_input
from .compilation import free_programs, keep_programs
from .model.types import Contact, ContactResult, ExchangeResult, State, Vehicle, VehicleResult
from .model.types import normal_from_angles, status_text
from .solve import Solution, solve, solve_inputs
from .sweeps import SweepResult, sweep

__all__ = [
    "Case",
    "CaseError",
    "CaseInputs",
    "Contact",
    "ContactResult",
    "ExchangeResult",
    "Solution",
    "State",
    "SweepResult",
    "Vehicle",
    "VehicleResult",
    "exchange",
    "exchange_batch",
    "free_programs",
    "get_input",
    "get_output",
    "keep_programs",
    "load_case",
    "load_cases",
    "normal_from_angles",
    "plot",
    "report",
    "set_input",
    "solve",
    "solve_inputs",
    "status_text",
    "sum_over_rows",
    "sweep",
    "units",
]
__version__ = "0.1.0"
