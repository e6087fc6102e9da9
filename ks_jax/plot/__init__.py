"""Pictures (the ``plot`` extra, matplotlib): the top view of a solved contact (``top_view``; a whole figure of
them, ``top_view_figure``), a sweep's results over its inputs (``sweep_view``; a figure of several,
``sweep_figure``) and a fit's samples (``corner``)."""

from pathlib import Path

from ..case.errors import CaseError
from ..files import check_output_file
from .corner import corner, save_corner
from .sweep_view import save_sweep_view, sweep_figure, sweep_view
from .top_view import save_top_view, top_view, top_view_figure

PICTURE_TYPES = (".png", ".pdf", ".svg")


def check_picture_path(path, option="--plot"):
    """Raise CaseError unless matplotlib is installed and ``path`` names a .png, .pdf or .svg file that
    can be written: called before anything is solved, so that a bad picture name loses no work."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise CaseError(f"{option} needs matplotlib: pip install 'ks-jax[plot]'") from None
    suffix = Path(path).suffix
    if suffix.lower() not in PICTURE_TYPES:
        raise CaseError(f"{option} {path}: unknown picture type '{suffix}' (use .png, .pdf or .svg)")
    check_output_file(path, option)


__all__ = ["PICTURE_TYPES", "check_picture_path", "corner", "save_corner", "save_sweep_view", "save_top_view",
           "sweep_figure", "sweep_view", "top_view", "top_view_figure"]
