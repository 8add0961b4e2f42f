"""Excitation of the synthetic stand: current ramps and dither amplitude shapes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...data.ramps import order_ramps
from ...errors import ModelError

__all__ = [
    "DITHER_SHAPES",
    "RAMPS",
    "DitherSetting",
    "RampProfile",
    "dither_amplitude",
    "order_ramps",
]


@dataclass(frozen=True)
class RampProfile:
    """0 → ``peak`` → 0 mA ramp with holds at both ends.

    Attributes
    ----------
    label : str
        Split key written to the manifest (fast / medium / slow).
    ramp_s : float
        Duration of each ramp (up, and down) in s.
    hold_s : float
        Hold at 0 mA before, at the peak between, and at 0 mA after the ramps (s).
    peak_mA : float
        Peak nominal current (mA).
    """

    label: str
    ramp_s: float
    hold_s: float = 1.0
    peak_mA: float = 1100.0

    @property
    def duration_s(self) -> float:
        """Total duration (s)."""
        return 3 * self.hold_s + 2 * self.ramp_s

    @property
    def rate_mA_s(self) -> float:
        """Ramp rate (mA/s)."""
        return self.peak_mA / self.ramp_s

    def current(self, t: np.ndarray) -> np.ndarray:
        """Nominal current (mA) at times ``t`` (s)."""
        h, r = self.hold_s, self.ramp_s
        knots = [0.0, h, h + r, 2 * h + r, 2 * h + 2 * r, 3 * h + 2 * r]
        return np.interp(t, knots, [0.0, 0.0, self.peak_mA, self.peak_mA, 0.0, 0.0])


#: The stand's three ramp rates (the paper's fast / medium / slow).
RAMPS: dict[str, RampProfile] = {
    "fast": RampProfile("fast", 2.5),
    "medium": RampProfile("medium", 10.0),
    "slow": RampProfile("slow", 40.0),
}


def _shape_a(i):  # flat: 100 mA, faded in over the first 100 mA
    return 100.0 * np.clip(i / 100.0, 0.0, 1.0)


def _shape_b(i):  # rising with current to 225 mA
    return 25.0 + 200.0 * np.clip(i / 1100.0, 0.0, 1.0)


def _shape_c(i):  # high at low current, falling to 40 mA
    return 40.0 + 160.0 * np.clip(1.0 - i / 800.0, 0.0, 1.0) * np.clip(i / 60.0, 0.0, 1.0)


#: Dither amplitude (mA) as a function of nominal current (mA); all within 0–225 mA.
DITHER_SHAPES = {"A": _shape_a, "B": _shape_b, "C": _shape_c}


def dither_amplitude(shape: str, current_mA: np.ndarray) -> np.ndarray:
    """Dither amplitude (mA) of amplitude shape ``shape`` at nominal current (mA)."""
    try:
        return DITHER_SHAPES[shape](np.asarray(current_mA, dtype=float))
    except KeyError:
        raise ModelError(
            f"unknown dither shape {shape!r}; known: {sorted(DITHER_SHAPES)}"
        ) from None


@dataclass(frozen=True)
class DitherSetting:
    """Dither frequency (Hz), amplitude shape and waveform of one experiment.

    Attributes
    ----------
    freq_Hz : float
        Dither frequency, Hz.
    shape : str
        Amplitude shape, a key of :data:`DITHER_SHAPES` (``"A"`` flat 100 mA, ``"B"``
        rising with current to 225 mA, ``"C"`` falling to 40 mA); amplitudes in mA.
    waveform : {"sine", "triangle", "square"}
        Dither waveform.
    """

    freq_Hz: float
    shape: str
    waveform: str = "sine"

    @property
    def tag(self) -> str:
        """Short file-name tag, e.g. ``50Hz_B``."""
        return f"{self.freq_Hz:g}Hz_{self.shape}"
