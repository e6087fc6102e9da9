"""Case files: from a JSON or TOML file to the inputs of a solve, and the paths that name single
inputs and results (docs/model.md, "Case files" and "Paths").

- ``load``: reading files into ``Case`` objects, every number converted to SI;
- ``fixed``: a wall, pole or barrier struck in place of a second vehicle;
- ``approach``: a vehicle's approach before the impact, its phases read (``inputs.ApproachInputs``);
- ``wheels``: how a vehicle's wheels run (its ``after``, an approach phase);
- ``hitch``: articulated vehicles, a towed vehicle's ``hitch`` read, and its position and velocity followed from its
  tow's (``follow_tows``);
- a ``road`` (``inputs.RoadInputs``): the vehicles move on from the exchange to rest;
- ``inputs``: ``CaseInputs``, the pytree of a case's inputs, and ``to_pytrees`` for the physics;
- ``schema``: what each field is (its kind of quantity and shape);
- ``paths``: getting and setting one number by its path ("vehicles[1].speed");
- ``outputs``: results the model leaves undefined in some rows, and why;
- ``scale``: scenes far from the origin in float32, and inputs far out of scale;
- ``fields``: reading one field (its units) and the words of the messages;
- ``errors``: ``CaseError`` and ``CaseWarning``, and ``visible``: a name from a file as a terminal may show it.
"""

from .errors import CaseError, CaseWarning, visible, visible_lines
from .hitch import follow_tows
from .inputs import AfterInputs, ApproachInputs, Case, CaseInputs, ContactInputs, HitchInputs, InteractionInputs
from .inputs import Motion, PairInputs, RoadInputs, VehicleInputs
from .inputs import as_arrays, body_states, to_pytrees
from .build import case_from_dict, parse_output_value
from .load import cases_from_data, load_case, load_cases
from .outputs import CIRCULAR_OUTPUTS, UNDEFINED_REASONS, at_rest_after, defined_output, impulse_exchanged
from .outputs import undefined_kind
from .paths import CUMULATIVE_OUTPUTS, PathError, automatic_part, canonical_path, check_output_path, follows_tow
from .paths import check_inputs, check_result, get_input
from .paths import get_output
from .paths import input_kind, input_leaf, input_ties, on_fixed_object, output_kind, parse_path, path_key
from .paths import AT_OUTPUTS, add_times, at_time, set_input, times_asked, with_times, without_approach, without_road
from .paths import without_time

__all__ = [
    "AT_OUTPUTS", "CUMULATIVE_OUTPUTS", "add_times", "at_time", "times_asked", "with_times", "without_time",
    "AfterInputs", "ApproachInputs", "CIRCULAR_OUTPUTS", "Motion", "RoadInputs", "UNDEFINED_REASONS", "Case",
    "CaseError", "CaseInputs",
    "CaseWarning", "ContactInputs", "HitchInputs", "InteractionInputs", "PairInputs", "PathError", "VehicleInputs",
    "as_arrays",
    "at_rest_after", "automatic_part", "body_states",
    "canonical_path", "case_from_dict", "cases_from_data", "check_inputs", "check_output_path", "check_result",
    "defined_output", "follow_tows",
    "follows_tow", "get_input",
    "get_output", "impulse_exchanged", "input_kind", "input_leaf", "input_ties", "load_case", "load_cases",
    "on_fixed_object", "output_kind", "parse_output_value", "parse_path", "path_key", "set_input", "to_pytrees",
    "undefined_kind", "visible", "visible_lines", "without_approach", "without_road",
]
