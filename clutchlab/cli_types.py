"""argparse value types and arguments shared by the ``clutchlab`` subcommands.

The types give range errors before any work.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = [
    "MAP_HELP",
    "MAX_NOTES_SHOWN",
    "add_map_argument",
    "nonnegative_float",
    "nonnegative_int",
    "positive_float",
    "positive_int",
    "print_dither_notes",
]

#: Help of ``--map`` on every command that reads test-stand logs.
MAP_HELP = (
    "channel map (TOML) for logs with other channel names or units: source channel → "
    "canonical signal, unit; applied to every experiment (over a dataset manifest's own "
    "channel_map)"
)


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


def add_map_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--map MAP.toml``, the channel map of the logs a command reads.

    The command passes it on as ``load_dataset(..., channel_map=args.map)`` (or to the
    check or conversion of one log), which reads the map before any experiment: a missing
    or malformed map is a :class:`~clutchlab.errors.DataError` naming the file (exit
    status 2), before any fit or other long work.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The subcommand's parser.
    """
    parser.add_argument("--map", metavar="MAP.toml", help=MAP_HELP)


#: Notes of one kind :func:`print_dither_notes` prints in full; the rest are named.
MAX_NOTES_SHOWN = 3


def print_dither_notes(dataset) -> None:
    """Print to stderr, before any work, the experiments of ``dataset`` whose dither the
    analyses cannot average out (no dither frequency given, a dither in the measured
    current: :func:`~clutchlab.data.demodulate.no_dither_frequency_note`) or do not know
    (a command-only log without a dither amplitude:
    :func:`~clutchlab.data.demodulate.no_dither_amplitude_note`), as ``data check`` lists
    them.

    Parameters
    ----------
    dataset : Dataset
        As loaded by :func:`~clutchlab.data.load_dataset` (its ``reports`` hold the notes).
    """
    import sys

    from .data.demodulate import NO_DITHER_AMPLITUDE, NO_DITHER_FREQUENCY

    for kind in (NO_DITHER_FREQUENCY, NO_DITHER_AMPLITUDE):
        found = [
            (report.file, note)
            for report in dataset.reports.values()
            for note in report.notes
            if note.startswith(kind)
        ]
        for file, note in found[:MAX_NOTES_SHOWN]:
            print(f"note: {file}: {note}", file=sys.stderr)
        if len(found) > MAX_NOTES_SHOWN:
            more = ", ".join(file.name for file, _ in found[MAX_NOTES_SHOWN:])
            print(
                f"note: {kind} either in {len(found) - MAX_NOTES_SHOWN} more experiment(s): "
                f"{more} (`clutchlab data check` lists each)",
                file=sys.stderr,
            )
