"""Checks of signal values against the data contract; each returns every problem it finds.

Every problem names the file (``where``), the column and the rows. The checks are:

- missing values: runs of NaN / inf (filled only when the caller allows gaps of that length);
- time: non-finite, duplicate or decreasing time stamps;
- implausible units: a whole column on the wrong scale (current in A, pressure in kPa / psi /
  Pa, temperature in °F / K, dither amplitude in A);
- physical range: single values outside the plausible range of the signal;
- sample rate below 10 × the dither frequency (the dither would not be resolved).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .signals import SIGNALS
from .trace import _MAX_ROWS_LISTED, Trace, _default_row_label

__all__ = [
    "MIN_SAMPLES_PER_DITHER_PERIOD",
    "check_dither_rate",
    "check_time",
    "check_values",
    "clutch_pressure_scale_note",
    "fill_runs",
    "nonfinite_runs",
    "validate_trace",
]

#: The sample rate must be at least this many times the dither frequency.
MIN_SAMPLES_PER_DITHER_PERIOD = 10.0

RowLabel = Callable[[int], str]

#: Below this share of the line pressure, a clutch pressure that never rises further gets a
#: note on its unit (a latching circuit reaches line pressure at high current).
LOW_CLUTCH_SHARE = 0.25
#: Nominal current (mA) above which a clutch circuit is expected to have latched.
LATCHED_CURRENT_MA = 1000.0


def _rows(idx: np.ndarray, row_label: RowLabel) -> str:
    shown = ", ".join(row_label(int(i)) for i in idx[:_MAX_ROWS_LISTED])
    if idx.size > _MAX_ROWS_LISTED:
        shown += f" … ({idx.size} rows in total)"
    return shown


def _span(start: int, stop: int, row_label: RowLabel) -> str:
    if stop - start == 1:
        return row_label(start)
    return f"{row_label(start)} to {row_label(stop - 1)}"


def nonfinite_runs(values: np.ndarray) -> list[tuple[int, int]]:
    """Runs of consecutive non-finite values.

    Parameters
    ----------
    values : numpy.ndarray
        1-D float values.

    Returns
    -------
    list of (int, int)
        ``(start, stop)`` index ranges (stop exclusive), in order.
    """
    bad = ~np.isfinite(values)
    if not bad.any():
        return []
    edges = np.diff(np.concatenate([[0], bad.view(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()
    return list(zip(starts, stops, strict=True))


def fill_runs(t: np.ndarray, values: np.ndarray, runs: list[tuple[int, int]]) -> np.ndarray:
    """Fill runs of missing values: linear in time inside, nearest value at the ends.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s (finite, increasing).
    values : numpy.ndarray
        Values with the runs to fill (any unit).
    runs : list of (int, int)
        ``(start, stop)`` index ranges to fill.

    Returns
    -------
    numpy.ndarray
        A filled copy (unchanged if every value is missing).
    """
    out = np.array(values, dtype=np.float64)
    good = np.isfinite(out)
    if not good.any():
        return out
    fill = np.zeros(out.size, dtype=bool)
    for a, b in runs:
        fill[a:b] = True
    out[fill] = np.interp(t[fill], t[good], out[good])
    return out


def describe_runs(
    runs: list[tuple[int, int]], values: np.ndarray, row_label: RowLabel
) -> tuple[str, int]:
    """Text listing the runs (at most a few) and the length of the longest run."""
    shown = []
    for a, b in runs[:_MAX_ROWS_LISTED]:
        kinds = sorted(
            {"NaN" if np.isnan(v) else ("+inf" if v > 0 else "-inf") for v in values[a:b]}
        )
        shown.append(f"{_span(a, b, row_label)} ({b - a} × {'/'.join(kinds)})")
    more = f" … ({len(runs)} runs in total)" if len(runs) > _MAX_ROWS_LISTED else ""
    return "; ".join(shown) + more, max(b - a for a, b in runs)


def check_time(
    t: np.ndarray,
    where: str,
    row_label: RowLabel = _default_row_label,
    reported: np.ndarray | None = None,
) -> list[str]:
    """Problems of a time column: non-finite, duplicate or decreasing time stamps.

    Parameters
    ----------
    t : numpy.ndarray
        Time stamps, s.
    where : str
        Prefix naming file and column, e.g. ``"log.csv: column 'time_s'"``.
    row_label : callable, optional
        Maps a 0-based sample index to the text naming its row.
    reported : numpy.ndarray of bool, optional
        Samples whose problem the decoder already reported (unparseable cells, read as
        NaN): not reported again as non-finite.

    Returns
    -------
    list of str
    """
    problems = []
    missing = ~np.isfinite(t)
    if reported is not None and reported.shape == t.shape:
        missing &= ~reported
    bad = np.flatnonzero(missing)
    if bad.size:
        problems.append(f"{where}: non-finite value at {_rows(bad, row_label)}")
    pair = np.isfinite(t[1:]) & np.isfinite(t[:-1])
    dup = np.flatnonzero(pair & (t[1:] == t[:-1])) + 1
    if dup.size:
        i = int(dup[0])
        problems.append(
            f"{where}: duplicate time stamp at {_rows(dup, row_label)} "
            f"(first: {t[i]:.9g} s, same as {row_label(i - 1)})"
        )
    back = np.flatnonzero(pair & (t[1:] < t[:-1])) + 1
    if back.size:
        i = int(back[0])
        problems.append(
            f"{where}: not strictly increasing at {_rows(back, row_label)} "
            f"(first: {t[i]:.9g} s after {t[i - 1]:.9g} s)"
        )
    return problems


def _unit_problem(signal: str, values: np.ndarray) -> tuple[str, int] | None:
    """Text of an implausible-unit diagnosis for a whole column, and the row to show."""
    finite = np.isfinite(values)
    if not finite.any():
        return None
    absval = np.where(finite, np.abs(values), -np.inf)
    i_max = int(np.argmax(absval))
    peak = float(absval[i_max])
    if signal in ("current_mA", "current_cmd_mA") and 0.05 < peak < 5.0:
        return f"values look like amperes (largest |value| {peak:g}); the unit must be mA", i_max
    if signal == "dither_amp_mA" and 0.0 < peak <= 0.5:
        return f"values look like amperes (largest {peak:g}); the unit must be mA", i_max
    if signal.endswith("_pressure_bar"):
        if peak > 1e4:
            return f"values look like Pa (largest {peak:g}); the unit must be bar (gauge)", i_max
        if peak > 100.0:
            return (
                f"values look like kPa or psi (largest {peak:g}); the unit must be bar (gauge)",
                i_max,
            )
    if signal == "oil_temp_C" and SIGNALS[signal].plausible_max < peak <= 500.0:
        low = float(np.min(values[finite]))
        unit = "kelvin or °F" if low >= 233.15 else "°F"  # -40 °C = 233.15 K = -40 °F
        return f"values look like {unit} ({low:g} to {peak:g}); the unit must be °C", i_max
    return None


def _share_at_least(x: np.ndarray, level) -> float:
    """Share of the finite samples of ``x`` at or above ``level`` (a number, or one per
    sample); 0 when none is finite."""
    finite = np.count_nonzero(np.isfinite(x))
    return np.count_nonzero(x >= level) / finite if finite else 0.0


def clutch_pressure_scale_note(trace: Trace) -> str | None:
    """A note when the clutch pressure stays far below the line pressure although the
    current went high enough to latch: a unit off by a factor (psi declared as kPa reads
    6.9× low, bar as kPa 100×) that no range check catches.

    Parameters
    ----------
    trace : Trace
        One experiment, canonical signals (bar, mA).

    Returns
    -------
    str or None
        The note when the 99.5th percentile of ``clutch_pressure_bar`` is below
        :data:`LOW_CLUTCH_SHARE` of the median line pressure (17.7 bar when not logged) and
        the current (command, else measured) exceeds :data:`LATCHED_CURRENT_MA`; else None.
    """
    current = "current_cmd_mA" if trace.has("current_cmd_mA") else "current_mA"
    if not trace.has("clutch_pressure_bar") or not trace.has(current):
        return None
    i = np.asarray(trace.get(current), dtype=float)
    p = np.asarray(trace.get("clutch_pressure_bar"), dtype=float)
    if not (np.isfinite(i).any() and np.isfinite(p).any()):
        return None
    # "the 99.5th percentile is below x" read as "at most 0.5 % of the samples reach x":
    # counts, not sorts, so that every load of 10⁶ samples does not pay ~30 ms for a note
    if _share_at_least(i, LATCHED_CURRENT_MA) <= 0.005:
        return None
    logged = trace.has("line_pressure_bar")
    default = float(SIGNALS["line_pressure_bar"].default)
    line_at = np.asarray(trace.get("line_pressure_bar"), dtype=float) if logged else default
    if _share_at_least(p, LOW_CLUTCH_SHARE * line_at) > 0.005:
        return None
    line = float(np.nanmedian(line_at)) if logged else default  # for the note's text only
    if not line > 0:
        return None
    top = float(np.nanpercentile(p, 99.5))
    return (
        f"clutch pressure reaches at most {top:.3g} bar, {100 * top / line:.0f} % of the line "
        f"pressure ({line:.3g} bar{'' if logged else ', the default'}), although the current "
        f"goes above {LATCHED_CURRENT_MA:g} mA where a clutch circuit latches to line "
        "pressure: check the clutch pressure's unit (psi read as kPa is 6.9× low, bar read "
        "as kPa 100×)"
    )


def check_values(
    signal: str,
    values: np.ndarray,
    where: str,
    row_label: RowLabel = _default_row_label,
) -> list[str]:
    """Implausible-unit and out-of-range problems of one canonical signal's values.

    Parameters
    ----------
    signal : str
        Canonical signal name (its plausible range is in :data:`SIGNALS`).
    values : numpy.ndarray
        Values in the signal's canonical unit (non-finite values are ignored here).
    where : str
        Prefix naming file and column.
    row_label : callable, optional
        Maps a 0-based sample index to the text naming its row.

    Returns
    -------
    list of str
        At most one problem: a unit diagnosis for the whole column, or else the rows out of
        the plausible range.
    """
    spec = SIGNALS[signal]
    unit = _unit_problem(signal, values)
    if unit is not None:
        text, row = unit
        return [
            f"{where}: implausible unit: {text} (at {row_label(row)}); convert it, or declare "
            f"the unit in a channel map"
        ]
    with np.errstate(invalid="ignore"):
        out = np.flatnonzero(
            np.isfinite(values) & ((values < spec.plausible_min) | (values > spec.plausible_max))
        )
    if not out.size:
        return []
    shown = ", ".join(f"{row_label(int(i))} = {values[int(i)]:.6g}" for i in out[:_MAX_ROWS_LISTED])
    more = f" … ({out.size} rows in total)" if out.size > _MAX_ROWS_LISTED else ""
    return [
        f"{where}: value(s) outside the physical range [{spec.plausible_min:g}, "
        f"{spec.plausible_max:g}] {spec.unit} at {shown}{more}"
    ]


def check_dither_rate(
    rate_Hz: float,
    freq_Hz: np.ndarray | float,
    where: str,
    row_label: RowLabel = _default_row_label,
) -> list[str]:
    """Problem if the sample rate is below 10 × the dither frequency.

    Parameters
    ----------
    rate_Hz : float
        Sample rate of the trace, Hz.
    freq_Hz : numpy.ndarray or float
        Dither frequency per sample (the ``dither_freq_Hz`` column), or one value, Hz.
    where : str
        Names the source of ``freq_Hz`` (file and column, or manifest entry).
    row_label : callable, optional
        Maps a 0-based sample index to the text naming its row.

    Returns
    -------
    list of str
    """
    limit = rate_Hz / MIN_SAMPLES_PER_DITHER_PERIOD
    f = np.atleast_1d(np.asarray(freq_Hz, dtype=np.float64))
    with np.errstate(invalid="ignore"):
        # a rate measured off a grid of exactly 10 × the dither (499.99999… Hz for 50 Hz)
        # is that rate: a relative 1e-9 of rounding is not a rate too low
        bad = np.flatnonzero(np.isfinite(f) & (f > limit * (1.0 + 1e-9)))
    if not bad.size:
        return []
    rows = f" at {_rows(bad, row_label)}" if f.size > 1 else ""
    return [
        f"{where}: sample rate {rate_Hz:.6g} Hz is too low to resolve a dither of "
        f"{float(np.nanmax(f[bad])):.6g} Hz{rows}; it must be at least "
        f"{MIN_SAMPLES_PER_DITHER_PERIOD:g} × the dither frequency "
        f"({MIN_SAMPLES_PER_DITHER_PERIOD * float(np.nanmax(f[bad])):.6g} Hz)"
    ]


def validate_trace(trace: Trace) -> list[str]:
    """Every data-contract problem of an in-memory trace (what reading a file would refuse).

    Parameters
    ----------
    trace : Trace
        Trace to check.

    Returns
    -------
    list of str
        Problems naming the trace (or its source file), the column and the rows: NaN / inf
        runs, duplicate time stamps, implausible units, values out of the physical range,
        sample rate below 10 × the dither frequency (``dither_freq_Hz`` column, else
        ``meta["dither_freq_Hz"]``). Empty if the trace is fine.
    """
    name = str(trace.source) if trace.source is not None else f"trace {trace.name!r}"
    problems = check_time(trace.time_s, f"{name}: column 'time_s'")
    for signal, values in trace.signals.items():
        if signal == "time_s":
            continue
        where = f"{name}: column {signal!r}"
        runs = nonfinite_runs(values)
        if runs:
            text, _ = describe_runs(runs, values, _default_row_label)
            problems.append(f"{where}: missing values (NaN/inf) at {text}")
        problems += check_values(signal, values, where)
    if len(trace) >= 2 and not problems:
        rate = trace.sample_rate_Hz
        if trace.has("dither_freq_Hz"):
            problems += check_dither_rate(
                rate, trace.get("dither_freq_Hz"), f"{name}: column 'dither_freq_Hz'"
            )
        elif isinstance(trace.meta.get("dither_freq_Hz"), int | float):
            problems += check_dither_rate(
                rate, float(trace.meta["dither_freq_Hz"]), f"{name}: meta 'dither_freq_Hz'"
            )
    return problems
