"""Typed settings of the hysteresis and latch analysis used by the validation metrics."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["AnalysisSettings"]


@dataclass(frozen=True)
class AnalysisSettings:
    """How branches, hysteresis bins and latch snaps are found (DESIGN §5 metrics).

    Attributes
    ----------
    bin_mA : float
        Width of the nominal-current bins of the hysteresis analysis, mA (default 25).
    min_samples : int
        Fewest samples of one branch in a bin for the bin to count (default 10).
    min_coverage : float
        Fewest current span of one branch inside a bin, as a fraction of ``bin_mA``
        (default 0.5): the branch value at the bin centre is interpolated, never
        extrapolated far.
    min_rate_mA_s : float
        A sample belongs to the rising (falling) branch when the filtered dI/dt of the
        nominal current is above ``+rate`` (below ``-rate``), with
        ``rate = max(min_rate_mA_s, rel_rate · P90(|dI/dt|))``; holds belong to neither
        (mA/s, default 2).
    rel_rate : float
        Relative part of the branch threshold (default 0.1, see ``min_rate_mA_s``).
    latch_margin_bar : float
        The clutch pressure counts as latched (snapped to line pressure) when it is within
        this margin of the measured line pressure, bar (default 1.0; the stand's regulated
        pressure stays ≥ 2.5 bar below line pressure before the snap).
    plateau_guard_s : float
        The latched-plateau error leaves out samples this close to a latch snap or release
        of either signal (s, default 0.05): the snap itself is latch timing, which the
        latch-current errors score.
    latch_window_s : float
        Half-width of the latch window of the coverage metric (s, default 0.15): the
        samples around a measured snap or release, where a wrong latch time lands.
    """

    bin_mA: float = 25.0
    min_samples: int = 10
    min_coverage: float = 0.5
    min_rate_mA_s: float = 2.0
    rel_rate: float = 0.1
    latch_margin_bar: float = 1.0
    plateau_guard_s: float = 0.05
    latch_window_s: float = 0.15

    def __post_init__(self) -> None:
        problems = []
        if not self.bin_mA > 0:
            problems.append(f"bin_mA must be > 0, got {self.bin_mA!r}")
        if self.min_samples < 2:
            problems.append(f"min_samples must be ≥ 2, got {self.min_samples!r}")
        if not 0 <= self.min_coverage <= 1:
            problems.append(f"min_coverage must be in [0, 1], got {self.min_coverage!r}")
        if not self.min_rate_mA_s > 0 or not self.rel_rate >= 0:
            problems.append("min_rate_mA_s must be > 0 and rel_rate ≥ 0")
        if not self.latch_margin_bar > 0:
            problems.append(f"latch_margin_bar must be > 0, got {self.latch_margin_bar!r}")
        if not self.latch_window_s >= 0:
            problems.append(f"latch_window_s must be ≥ 0, got {self.latch_window_s!r}")
        if not self.plateau_guard_s >= 0:
            problems.append(f"plateau_guard_s must be ≥ 0, got {self.plateau_guard_s!r}")
        if problems:
            raise ValueError("invalid analysis settings: " + "; ".join(problems))
