"""Option types shared by the commands (argparse: a bad value is a usage error, exit status 2)."""

from __future__ import annotations

import argparse


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def smoothing_option(text: str) -> float:
    """``--smoothing``: a number in [0, 1)."""
    tau = _number(text)
    if not 0.0 <= tau < 1.0:  # NaN fails too
        raise argparse.ArgumentTypeError(f"{text}: smoothing must be in [0, 1)")
    return tau


def acceptance_option(text: str) -> float:
    """``--target-acceptance``: a number in (0, 1)."""
    target = _number(text)
    if not 0.0 < target < 1.0:  # NaN fails too
        raise argparse.ArgumentTypeError(f"{text}: the target acceptance must be in (0, 1)")
    return target


def seed_option(text: str) -> int:
    """``--seed``: a whole number >= 0 (NumPy's generators take no negative seed)."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if seed < 0:
        raise argparse.ArgumentTypeError(f"{text}: a seed must be 0 or more")
    return seed
