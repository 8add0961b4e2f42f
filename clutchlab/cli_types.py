"""argparse value types shared by the ``clutchlab`` subcommands: range errors before any work."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["nonnegative_float", "nonnegative_int", "positive_float", "positive_int"]


def _parse(text: str, cast: Callable[[str], float], what: str) -> float:
    try:
        return cast(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None


def positive_float(text: str) -> float:
    """A finite number > 0 (a time limit or timeout in s)."""
    value = _parse(text, float, "a number")
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: a finite number > 0 is needed")
    return value


def nonnegative_float(text: str) -> float:
    """A finite number >= 0 (an interval in s where 0 means "every time")."""
    value = _parse(text, float, "a number")
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be ≥ 0 s and finite, not {text}")
    return value


def nonnegative_int(text: str) -> int:
    """An integer >= 0 (a seed)."""
    value = int(_parse(text, int, "an integer"))
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; an integer >= 0 is needed")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (a count of worker processes)."""
    value = int(_parse(text, int, "an integer"))
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, not {value}")
    return value
