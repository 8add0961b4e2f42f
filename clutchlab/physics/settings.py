"""Typed settings of the simulator."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..data.signals import SIGNALS
from ..errors import ModelError

__all__ = [
    "COARSE_INTERVAL_S",
    "MAX_CHUNK",
    "MAX_SETTLE_S",
    "MAX_STEP_S",
    "MAX_SUBSTEPS",
    "SimulationSettings",
    "steps_per_interval",
]

#: Largest ROS2 step (s) on data sampled slower than 1 kHz: what 1 kHz data give with the
#: fit's 2 substeps. Steps of 2.5–10 ms (100 Hz data at 4 or 1 substeps) produced pressures
#: of −28 to −7376 bar.
MAX_STEP_S = 0.5e-3

#: Sample intervals (s) up to this (1 kHz and faster, with a margin for the rounding of
#: logged time stamps) are integrated in exactly ``substeps`` ROS2 steps: results on such
#: data do not depend on :data:`MAX_STEP_S`.
COARSE_INTERVAL_S = 1e-3 * (1.0 + 1e-6)

#: Longest settling run (s): the circuit's lags are below 0.1 s, and the run holds one
#: state row per sample interval (10⁶ s at 1 kHz asked for 89 GiB).
MAX_SETTLE_S = 60.0

#: Most ROS2 substeps per sample interval (the generated code grows with the count).
MAX_SUBSTEPS = 64

#: Most samples per call of the compiled loop (its code and buffers grow with the count).
MAX_CHUNK = 100_000


@dataclass(frozen=True)
class SimulationSettings:
    """How a trace is simulated.

    Attributes
    ----------
    method : {"ros2", "radau"}
        ``ros2``: fixed-step, L-stable, linearly implicit Rosenbrock method of
        order 2 (Verwer et al. 1999), compiled to C — fast, what fitters and the
        FMU use. ``radau``: SciPy's adaptive Radau IIA with ``rtol``/``atol`` — a
        slow reference for accuracy checks.
    substeps : int
        ROS2 steps per sample interval, 1 to :data:`MAX_SUBSTEPS` (1 kHz data, 4 substeps →
        0.25 ms steps). On data sampled slower than 1 kHz (median interval above 1 ms)
        the step is bounded instead: each sample interval is split into the fewest equal
        parts that make its steps at most :data:`MAX_STEP_S` (0.5 ms), the inputs
        interpolated linearly as within the substeps — in effect
        ``parts × substeps`` steps per sample (100 Hz data, 4 substeps: 5 parts, 20
        steps of 0.5 ms), see :func:`steps_per_interval`. Data at 1 kHz and faster are
        integrated with exactly ``substeps`` steps per sample, except across a gap
        (an interval above 1 ms), which is split as on coarse data.
    drive : {"auto", "command", "measured"}
        Excitation of the coil. ``measured`` uses the trace's measured current
        (dither included); ``command`` rebuilds the dithered command from nominal
        current, dither amplitude, frequency and waveform and passes it through
        the current loop. ``auto``: measured when ``current_mA`` is present.
    settle_s : float
        Duration (s) of a run at the first sample's inputs before the trace starts,
        so that the initial state is the operating point, not a guess; 0 to
        :data:`MAX_SETTLE_S` (60 s).
    compile : {"auto", "always", "never"}
        Generate and compile C for the ROS2 loop (cached on disk). ``auto``
        compiles when a C compiler is found, else interprets (slower, same result).
    chunk : int
        Samples per call of the compiled loop, 1 to :data:`MAX_CHUNK`.
    rtol, atol : float
        Tolerances of the ``radau`` method (relative, in (0, 1); absolute in scaled state
        units, > 0).
    dither_waveform : {"sine", "triangle", "square"}
        Waveform when the trace's metadata does not name one (``dither_waveform``).
    oil_temp_C : float
        Oil temperature (°C) when the trace has no ``oil_temp_C`` signal; within the
        signal's plausible range (−40 to 180 °C).
    out_of_range : {"warn", "raise", "ignore"}
        What :func:`~clutchlab.physics.simulate` does when a simulated pressure leaves the
        range the circuit can reach (below −1 bar or above 1.5 × line pressure; see
        :meth:`SimulationResult.out_of_range`): a fixed step too long for a design's
        dynamics can return ±10⁴ bar that are finite. ``warn`` (default) returns the
        result with a :class:`~clutchlab.errors.SimulationWarning`, ``raise`` raises a
        :class:`~clutchlab.errors.SimulationError` (design sweeps: the point is
        ``failed``), ``ignore`` returns it without a word.

    Raises
    ------
    ModelError
        Listing every invalid setting (a value of the wrong type, not finite or out of
        its range).
    """

    method: Literal["ros2", "radau"] = "ros2"
    substeps: int = 4
    drive: Literal["auto", "command", "measured"] = "auto"
    settle_s: float = 0.5
    compile: Literal["auto", "always", "never"] = "auto"
    chunk: int = 1000
    rtol: float = 1e-8
    atol: float = 1e-9
    dither_waveform: Literal["sine", "triangle", "square"] = "sine"
    oil_temp_C: float = 40.0
    out_of_range: Literal["warn", "raise", "ignore"] = "warn"

    def __post_init__(self) -> None:
        problems = []
        if self.method not in ("ros2", "radau"):
            problems.append(f"method {self.method!r} is not 'ros2' or 'radau'")
        if not is_integer(self.substeps) or not 1 <= self.substeps <= MAX_SUBSTEPS:
            problems.append(f"substeps {self.substeps!r} is not an integer in 1..{MAX_SUBSTEPS}")
        if self.drive not in ("auto", "command", "measured"):
            problems.append(f"drive {self.drive!r} is not auto, command or measured")
        if self.compile not in ("auto", "always", "never"):
            problems.append(f"compile {self.compile!r} is not auto, always or never")
        if not is_finite_real(self.settle_s) or not 0 <= self.settle_s <= MAX_SETTLE_S:
            problems.append(f"settle_s {self.settle_s!r} is not a number in 0..{MAX_SETTLE_S:g} s")
        if not is_integer(self.chunk) or not 1 <= self.chunk <= MAX_CHUNK:
            problems.append(f"chunk {self.chunk!r} is not an integer in 1..{MAX_CHUNK}")
        if not is_finite_real(self.rtol) or not 0 < self.rtol < 1:
            problems.append(f"rtol {self.rtol!r} is not a number in (0, 1)")
        if not is_finite_real(self.atol) or not self.atol > 0:
            problems.append(f"atol {self.atol!r} is not a finite number > 0")
        if self.dither_waveform not in ("sine", "triangle", "square"):
            problems.append(f"dither_waveform {self.dither_waveform!r} unknown")
        oil = SIGNALS["oil_temp_C"]
        if not is_finite_real(self.oil_temp_C) or not (
            oil.plausible_min <= self.oil_temp_C <= oil.plausible_max
        ):
            problems.append(
                f"oil_temp_C {self.oil_temp_C!r} is not a number in "
                f"{oil.plausible_min:g}..{oil.plausible_max:g} °C"
            )
        if self.out_of_range not in ("warn", "raise", "ignore"):
            problems.append(f"out_of_range {self.out_of_range!r} is not warn, raise or ignore")
        if problems:
            raise ModelError("invalid simulation settings: " + "; ".join(problems))


def is_integer(value) -> bool:
    """An integer (a Python or NumPy one), not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def is_finite_real(value) -> bool:
    """A finite real number, not a bool."""
    return (
        isinstance(value, numbers.Real)
        and not isinstance(value, bool)
        and math.isfinite(float(value))
    )


def steps_per_interval(t: np.ndarray, substeps: int) -> np.ndarray | None:
    """Parts each sample interval of ``t`` is split into so that its ROS2 steps stay short.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times (s), N ≥ 1, non-decreasing.
    substeps : int
        ROS2 steps per part (:attr:`SimulationSettings.substeps`).

    Returns
    -------
    numpy.ndarray or None
        None when no interval needs splitting; else the number of parts (int, ≥ 1) of each
        of the N − 1 intervals, the smallest with ``dt / (parts × substeps) ≤ MAX_STEP_S``.
        On data sampled at 1 kHz or faster (median interval at most
        :data:`COARSE_INTERVAL_S`) the intervals up to :data:`COARSE_INTERVAL_S` stay one
        part each (exactly ``substeps`` steps per sample, as before) and only the longer
        ones, gaps in the grid, are split: a 1 kHz trace with one 0.7 s gap was
        integrated over the gap in ``substeps`` steps of 175 ms.
    """
    dt = np.diff(np.asarray(t, dtype=float))
    if dt.size == 0:
        return None
    # the tolerance keeps an interval of exactly parts × substeps × MAX_STEP_S whole
    parts = np.ceil(dt / (substeps * MAX_STEP_S) * (1.0 - 1e-9)).astype(np.int64)
    parts = np.maximum(parts, 1)
    if float(np.median(dt)) <= COARSE_INTERVAL_S:
        parts[dt <= COARSE_INTERVAL_S] = 1
    return None if np.all(parts == 1) else parts
