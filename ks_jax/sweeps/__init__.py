"""Sweeps at scale: one case solved at every point of a grid or a list of samples of some of its
inputs, with only the chosen results kept (docs/sweeps.md).

- ``engine``: ``sweep``, chunk by chunk (memory bounded), sharded over the devices;
- ``result``: ``SweepResult``, and thinned views of it for pictures (``SweepSample``);
- ``columns``: the points as flat columns, in SI or US units;
- ``files``: ``ResultWriter`` and ``write_results``: .csv, .npz or .parquet, chunk by chunk.
"""

from .engine import default_outputs, sweep
from .files import ResultWriter, write_results
from .result import SweepResult, SweepSample, check_kept, plot_strides

__all__ = ["ResultWriter", "SweepResult", "SweepSample", "check_kept", "default_outputs", "plot_strides", "sweep",
           "write_results"]
