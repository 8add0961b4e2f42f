"""Typed settings of the simulator."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..errors import ModelError

__all__ = ["SimulationSettings"]


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
        ROS2 steps per sample interval (1 kHz data, 4 substeps → 0.25 ms steps).
    drive : {"auto", "command", "measured"}
        Excitation of the coil. ``measured`` uses the trace's measured current
        (dither included); ``command`` rebuilds the dithered command from nominal
        current, dither amplitude, frequency and waveform and passes it through
        the current loop. ``auto``: measured when ``current_mA`` is present.
    settle_s : float
        Duration (s) of a run at the first sample's inputs before the trace starts,
        so that the initial state is the operating point, not a guess.
    compile : {"auto", "always", "never"}
        Generate and compile C for the ROS2 loop (cached on disk). ``auto``
        compiles when a C compiler is found, else interprets (slower, same result).
    chunk : int
        Samples per call of the compiled loop.
    rtol, atol : float
        Tolerances of the ``radau`` method (relative; absolute in scaled state units).
    dither_waveform : {"sine", "triangle", "square"}
        Waveform when the trace's metadata does not name one (``dither_waveform``).
    oil_temp_C : float
        Oil temperature (°C) when the trace has no ``oil_temp_C`` signal.
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

    def __post_init__(self) -> None:
        problems = []
        if self.method not in ("ros2", "radau"):
            problems.append(f"method {self.method!r} is not 'ros2' or 'radau'")
        if not (1 <= self.substeps <= 64):
            problems.append(f"substeps {self.substeps} not in 1..64")
        if self.drive not in ("auto", "command", "measured"):
            problems.append(f"drive {self.drive!r} is not auto, command or measured")
        if self.compile not in ("auto", "always", "never"):
            problems.append(f"compile {self.compile!r} is not auto, always or never")
        if self.settle_s < 0:
            problems.append("settle_s must be ≥ 0")
        if self.chunk < 1:
            problems.append("chunk must be ≥ 1")
        if self.dither_waveform not in ("sine", "triangle", "square"):
            problems.append(f"dither_waveform {self.dither_waveform!r} unknown")
        if problems:
            raise ModelError("invalid simulation settings: " + "; ".join(problems))
