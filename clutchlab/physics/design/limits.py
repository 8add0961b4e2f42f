"""Size limits of a design sweep, checked when the spec is validated (before any allocation).

A spec beyond a limit is refused with the limit and the environment variable that raises it,
so a typo (``n = 1e9``, a 1000⁶ grid, ``ramp_s = 1e7``) fails at once instead of exhausting
memory. Defaults fit a large study on a workstation.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

__all__ = ["SweepLimits"]


@dataclass(frozen=True)
class SweepLimits:
    """Limits of one sweep.

    Attributes
    ----------
    max_points : int
        Design points (``CLUTCHLAB_SWEEP_MAX_POINTS``; default 1 000 000).
    max_simulated_s : float
        Simulated time of one design point: every ramp and the step, s
        (``CLUTCHLAB_SWEEP_MAX_SIMULATED_S``; default 600 s).
    """

    max_points: int = 1_000_000
    max_simulated_s: float = 600.0

    @classmethod
    def from_env(cls) -> SweepLimits:
        """The limits, each raised by its environment variable when set."""
        kw: dict = {}
        points = os.environ.get("CLUTCHLAB_SWEEP_MAX_POINTS", "").strip()
        if points.isdigit():
            kw["max_points"] = int(points)
        seconds = os.environ.get("CLUTCHLAB_SWEEP_MAX_SIMULATED_S", "").strip()
        try:
            if seconds:
                kw["max_simulated_s"] = float(seconds)
        except ValueError:
            pass
        return cls(**kw)
