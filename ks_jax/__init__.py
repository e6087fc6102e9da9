"""ks-jax: the Kudlich-Slibar impulse-momentum collision model in JAX.

See MODEL.md (the contract) for frames, equations and result names. Public surface:
``Vehicle``, ``State``, ``Contact``, ``exchange``, ``exchange_batch``, ``sum_over_rows``, ``load_case``, ``solve``, ``sweep``, ``units``,
``keep_programs`` (programs kept between processes, as the command line keeps them);
``ks_jax.plot`` (matplotlib) loads on first use.
"""

from . import units
from .case import Case, CaseError, CaseInputs, get_output, get_input, load_case, load_cases, set_input
from .batch import exchange_batch, sum_over_rows
from .exchange import exchange
from .solve import Solution, solve, solve_inputs
from .stored import keep_programs
from .sweeps import SweepResult, sweep
from .types import (
    Contact,
    ContactResult,
    ExchangeResult,
    State,
    Vehicle,
    VehicleResult,
    normal_from_angles,
    status_text,
)

__all__ = [
    "Case",
    "CaseError",
    "CaseInputs",
    "Solution",
    "get_input",
    "get_output",
    "load_case",
    "load_cases",
    "set_input",
    "solve",
    "solve_inputs",
    "sweep",
    "SweepResult",
    "Contact",
    "ContactResult",
    "ExchangeResult",
    "State",
    "Vehicle",
    "VehicleResult",
    "exchange",
    "exchange_batch",
    "keep_programs",
    "normal_from_angles",
    "status_text",
    "sum_over_rows",
    "units",
]
__version__ = "0.1.0"


def __getattr__(name):
    # submodules with optional dependencies (matplotlib) or heavier imports load on first use
    if name in ("plot", "geometry"):
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'ks_jax' has no attribute {name!r}")
