"""What the "dither-period mean" of a report really is on its experiments.

The primary scores average the measured and predicted clutch pressure over one dither period
of each experiment (:func:`~clutchlab.data.dither_period_samples`). A log without a dither
(no dither frequency logged, given in the manifest or found in the measured current) has a
period of one sample: its "dither-period mean" is the raw signal. A log whose dither
frequency is logged while its dither amplitude is 0 is averaged over one period of that
frequency: a moving average of an undithered signal. The report says which, per experiment,
instead of calling every one of them a dither-period mean.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["averaging_note", "averaging_window", "largest_dither_amp", "scored_signal"]

#: What the report calls the primary signal when every experiment has a dither.
PERIOD_MEAN = "dither-period mean"


def largest_dither_amp(trace: Any) -> float | None:
    """Largest finite logged dither amplitude of ``trace``, mA.

    Parameters
    ----------
    trace : Trace
        One experiment.

    Returns
    -------
    float or None
        None when the log has no ``dither_amp_mA`` or it is never finite.
    """
    if not trace.has("dither_amp_mA"):
        return None
    x = np.asarray(trace.get("dither_amp_mA"), dtype=float)
    x = x[np.isfinite(x)]
    return float(x.max()) if x.size else None


def averaging_window(
    period_samples: float, sample_rate_Hz: float, dither_amp_max_mA: float | None = None
) -> dict[str, Any]:
    """The averaging window of one experiment's primary scores.

    Parameters
    ----------
    period_samples : float
        Samples per dither period (1.0 without a dither).
    sample_rate_Hz : float
        Sample rate of the log, Hz.
    dither_amp_max_mA : float, optional
        Largest logged dither amplitude, mA (None when the log has no ``dither_amp_mA``).

    Returns
    -------
    dict
        ``samples`` (window length in samples), ``window_ms`` (its length, ms),
        ``dither_freq_Hz`` (the frequency whose period it is; None without a dither),
        ``dither_amp_max_mA`` (as given) and ``kind``: ``"dither_period"``, ``"none"`` (one
        sample: the raw signal) or ``"no_dither_amplitude"`` (a period of the logged dither
        frequency while the logged dither amplitude is 0 throughout).
    """
    n = float(period_samples)
    fs = float(sample_rate_Hz)
    if n <= 1.0:
        kind = "none"
    elif dither_amp_max_mA is not None and not dither_amp_max_mA > 0:
        kind = "no_dither_amplitude"
    else:
        kind = "dither_period"
    return {
        "samples": n,
        "window_ms": 1000.0 * n / fs if fs > 0 else None,
        "dither_freq_Hz": fs / n if n > 1.0 and fs > 0 else None,
        "dither_amp_max_mA": dither_amp_max_mA,
        "kind": kind,
    }


def _kinds(windows: Mapping[str, Mapping[str, Any]]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for name, w in windows.items():
        out.setdefault(str(w.get("kind", "dither_period")), []).append(name)
    return out


def scored_signal(windows: Mapping[str, Mapping[str, Any]] | None) -> str:
    """A short name of the primary signal, for headings, axis labels and captions.

    Parameters
    ----------
    windows : mapping of str to dict, or None
        Experiment → :func:`averaging_window`; None or empty (a report written before the
        windows were recorded): ``"dither-period mean"``.

    Returns
    -------
    str
        ``"dither-period mean"`` when every experiment is averaged over a period of its
        dither; ``"raw signal — no dither to average over"`` when none has a dither; otherwise
        ``"dither-period mean where dithered, else raw"`` or, with a logged frequency but
        a zero amplitude, a wording that says so.
    """
    if not windows:
        return PERIOD_MEAN
    kinds = _kinds(windows)
    if set(kinds) == {"dither_period"}:
        return PERIOD_MEAN
    if set(kinds) == {"none"}:
        return "raw signal — no dither to average over"
    if set(kinds) == {"no_dither_amplitude"}:
        return "moving average over one period of the logged dither frequency (amplitude 0)"
    if "no_dither_amplitude" in kinds and "none" not in kinds:
        return "mean over one period of the dither frequency; some logs have no dither"
    return f"{PERIOD_MEAN} where dithered, else raw"


def _ms(w: Mapping[str, Any]) -> str:
    """The window as ``"20 ms = 1/50 Hz"`` (in samples when the sample rate is unknown)."""
    ms = w.get("window_ms")
    hz = w.get("dither_freq_Hz")
    if ms is None:
        return f"{w.get('samples', float('nan')):.3g} samples"
    return f"{ms:.3g} ms" + (f" = 1/{hz:.3g} Hz" if hz else "")


def averaging_note(
    windows: Mapping[str, Mapping[str, Any]] | None, noun: str = "experiment"
) -> str:
    """A sentence saying over what the primary scores are averaged, per experiment.

    Parameters
    ----------
    windows : mapping of str to dict, or None
        Experiment → :func:`averaging_window`; None or empty: ``""``.
    noun : str
        What the experiments are called (``"test experiment"`` in an evaluation report,
        whose training experiments may have a dither where its test ones have none).

    Returns
    -------
    str
        E.g. ``"Primary signal: averaged over one dither period: 20 ms = 1/50 Hz
        (medium_50Hz_A)."``; for experiments
        without a dither it says that their primary scores are the raw ones (a window of 1
        sample), and for a logged frequency with a zero amplitude that the window is a
        moving average of an undithered signal.
    """
    if not windows:
        return ""
    kinds = _kinds(windows)
    parts = []
    groups: dict[str, list[str]] = {}
    for name in kinds.get("dither_period", []):
        groups.setdefault(_ms(windows[name]), []).append(name)
    if groups:
        parts.append(
            "averaged over one dither period: "
            + "; ".join(f"{ms} ({', '.join(names)})" for ms, names in groups.items())
        )
    if kinds.get("no_dither_amplitude"):
        names = kinds["no_dither_amplitude"]
        w = windows[names[0]]
        parts.append(
            f"{', '.join(names)}: logged dither amplitude 0 mA throughout, so the window "
            f"({_ms(w)}, the period of the logged dither frequency) is a moving average of an "
            "undithered signal, not a dither-period mean"
        )
    if kinds.get("none"):
        names = kinds["none"]
        who = f"no {noun} has" if len(names) == len(windows) else f"{', '.join(names)}: no"
        parts.append(
            f"{who} dither (no dither frequency logged, in the manifest or found in the "
            "measured current), so the averaging window is 1 sample and the primary scores "
            "are those of the raw signal"
        )
    return "Primary signal: " + "; ".join(parts) + "."
