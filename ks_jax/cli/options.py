"""Option types shared by the commands (argparse: a bad value is a usage error, exit status 2)."""

from __future__ import annotations

import argparse


def smoothing_option(text: str) -> float:
    """``--smoothing``: a number in [0, 1)."""
    try:
        tau = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= tau < 1.0:  # NaN fails too
        raise argparse.ArgumentTypeError(f"{text}: smoothing must be in [0, 1)")
    return tau


def seed_option(text: str) -> int:
    """``--seed``: a whole number >= 0 (NumPy's generators take no negative seed)."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if seed < 0:
        raise argparse.ArgumentTypeError(f"{text}: a seed must be 0 or more")
    return seed
