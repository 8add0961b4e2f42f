"""argparse value types shared by the ``clutchlab`` subcommands: range errors before any work."""

from __future__ import annotations

import argparse
import math

__all__ = ["nonnegative_int", "positive_float"]


def positive_float(text: str) -> float:
    """A finite number > 0 (a time limit or timeout in s)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: a finite number > 0 is needed")
    return value


def nonnegative_int(text: str) -> int:
    """An integer >= 0 (a seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; an integer >= 0 is needed")
    return value
