"""Output files: checked before any work starts, so that a bad name loses no work."""

from __future__ import annotations

import tempfile
from pathlib import Path

from .case.errors import CaseError


def check_output_file(path, option: str):
    """Raise CaseError unless ``path`` can be written: its folder exists and it is not a folder itself.
    ``option`` names where the path came from (``--out``, ``--plot``)."""
    target = Path(path)
    folder = target.parent
    if target.is_dir():
        raise CaseError(f"{option} {path}: is a folder; give a file name")
    if not folder.is_dir():
        why = "is a file, not a folder" if folder.exists() else "does not exist"
        raise CaseError(f"{option} {path}: the folder '{folder}' {why}")
    try:  # the folder's permissions, and a file system that refuses files whatever they say
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".ks-jax-check-"):
            pass
    except OSError as err:
        raise CaseError(f"{option} {path}: cannot write in the folder '{folder}' ({err.strerror or err})") from None
