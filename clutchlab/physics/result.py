"""Simulation result: outputs and states on the trace's time grid."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ModelError, SimulationError
from .model import OutputSpec
from .parameters import ParameterSet

if TYPE_CHECKING:  # pandas is imported on use: simulation workers start faster without it
    import pandas as pd

__all__ = ["PHYSICAL_PRESSURE_LINE_FACTOR", "PHYSICAL_PRESSURE_MIN_BAR", "SimulationResult"]

#: Lowest gauge pressure (bar) a simulated pressure may reach: oil cannot be pulled below
#: vacuum, and the model's solution with accurate steps stays above the exhaust pressure.
PHYSICAL_PRESSURE_MIN_BAR = -1.0

#: Highest simulated pressure as a multiple of the highest line pressure: nothing in the
#: circuit raises oil above its supply by more than the small transients of spool and piston
#: motion (about 1.3 bar on the datasheet circuit).
PHYSICAL_PRESSURE_LINE_FACTOR = 1.5


@dataclass(frozen=True)
class SimulationResult:
    """What :func:`simulate` returns.

    Attributes
    ----------
    time_s : ndarray
        Sample times (s).
    outputs : dict of str to ndarray
        Model outputs per sample (``clutch_pressure_bar`` is what the sensor reads).
    states : ndarray
        States per sample (N × nx), scaled engineering units (see ``state_units``).
    state_names, state_units : tuple of str
        Names and units of the state columns.
    output_specs : tuple of OutputSpec
        Units and descriptions of the outputs.
    params : ParameterSet
        Parameter values used.
    drive : str
        ``measured`` or ``command``.
    trace_name : str
        Name of the simulated experiment.
    wall_s : float
        Wall-clock time of the simulation (s).
    inputs : dict of str to ndarray
        Current and dither inputs used (for plots against current).
    """

    time_s: np.ndarray
    outputs: dict[str, np.ndarray]
    states: np.ndarray
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    output_specs: tuple[OutputSpec, ...]
    params: ParameterSet
    drive: str
    trace_name: str
    wall_s: float
    inputs: dict[str, np.ndarray] = field(default_factory=dict)

    def __repr__(self) -> str:
        # the dataclass repr printed every output array and the whole parameter set
        t = self.time_s
        span = f"{t[0]:.6g}–{t[-1]:.6g} s" if len(t) else "empty"
        return (
            f"SimulationResult(trace={self.trace_name!r}, {len(t)} samples, {span}, "
            f"drive={self.drive!r}, outputs=[{', '.join(self.outputs)}], "
            f"wall_s={self.wall_s:.3g})"
        )

    @property
    def pressure_bar(self) -> np.ndarray:
        """Clutch pressure as the sensor reads it (bar)."""
        return self.outputs["clutch_pressure_bar"]

    def out_of_range(self) -> str | None:
        """Why a simulated pressure is unphysical, or None when every one is in range.

        A fixed-step integration whose step is too long for a design's dynamics (e.g. a
        small chamber behind a large orifice) can stay finite and still be wrong by
        thousands of bar; no pressure of a circuit fed at line pressure falls below
        :data:`PHYSICAL_PRESSURE_MIN_BAR` or rises above
        :data:`PHYSICAL_PRESSURE_LINE_FACTOR` × the highest line pressure.

        Returns
        -------
        str or None
            Naming the first pressure output (bar) out of that range, its value and time,
            the range and the remedy (more ``substeps``, or ``method="radau"``).
        """
        line = self.inputs.get("line_pressure_bar")
        if line is None or not len(line):
            return None
        hi = PHYSICAL_PRESSURE_LINE_FACTOR * float(np.max(line))
        lo = PHYSICAL_PRESSURE_MIN_BAR
        for spec in self.output_specs:
            if spec.unit != "bar":
                continue
            p = np.asarray(self.outputs[spec.name])
            bad = np.flatnonzero((p < lo) | (p > hi))
            if bad.size:
                k = int(bad[0])
                return (
                    f"{self.trace_name}: {spec.name} = {p[k]:.6g} bar at t = "
                    f"{self.time_s[k]:.6g} s, outside the range the circuit can reach "
                    f"[{lo:g}, {hi:.4g}] bar ({PHYSICAL_PRESSURE_LINE_FACTOR:g} × line "
                    f"pressure): the integration step is too long for these parameters "
                    f"(raise substeps, or use method='radau'), or the design is unstable"
                )
        return None

    def check_pressures(self) -> None:
        """Raise when a simulated pressure leaves the range the circuit can physically reach
        (see :meth:`out_of_range`).

        Raises
        ------
        SimulationError
            With the message of :meth:`out_of_range`.
        """
        why = self.out_of_range()
        if why is not None:
            raise SimulationError(why)

    @property
    def real_time_factor(self) -> float:
        """Simulated time / wall time."""
        return float(self.time_s[-1] - self.time_s[0]) / max(self.wall_s, 1e-12)

    def units(self) -> dict[str, str]:
        """Unit of every column of :meth:`to_pandas`."""
        u = {"time_s": "s"} | {o.name: o.unit for o in self.output_specs}
        return u | {
            f"state_{n}": un for n, un in zip(self.state_names, self.state_units, strict=True)
        }

    def to_pandas(self, states: bool = False) -> pd.DataFrame:
        """Outputs (and optionally states, as ``state_<name>``) as a DataFrame; units in attrs."""
        cols = {"time_s": self.time_s} | dict(self.outputs)
        if states:
            cols |= {f"state_{n}": self.states[:, k] for k, n in enumerate(self.state_names)}
        import pandas as pd

        df = pd.DataFrame(cols)
        df.attrs["units"] = {k: v for k, v in self.units().items() if k in df.columns}
        df.attrs["trace"] = self.trace_name
        return df

    def plot(self, measured=None, axes=None):
        """Pressure vs time and pressure vs current.

        Parameters
        ----------
        measured : Trace, optional
            Overlay its measured clutch pressure: the trace that was simulated, on the same
            time grid (slice it as the simulated one was).
        axes : pair of matplotlib Axes, optional
            Where to draw; a new figure when omitted.

        Returns
        -------
        matplotlib.figure.Figure

        Raises
        ------
        ModelError
            If ``measured`` is not on this result's time grid (another trace, or the whole
            trace of a simulated slice): its pressure would be drawn against this result's
            current.
        """
        if measured is not None:
            self._check_same_grid(measured)
        import matplotlib.pyplot as plt

        if axes is None:
            fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
        else:
            fig = axes[0].figure
        ax_t, ax_i = axes
        current = self.inputs.get("current_nom_mA")
        if current is None or not np.any(current):
            current = self.outputs["coil_current_mA"]
        if measured is not None:
            ax_t.plot(
                measured.time_s,
                measured.get("clutch_pressure_bar"),
                color="0.6",
                lw=0.6,
                label="measured",
            )
            ax_i.plot(
                current, measured.get("clutch_pressure_bar"), color="0.6", lw=0.6, label="measured"
            )
        ax_t.plot(self.time_s, self.pressure_bar, lw=0.9, label="simulated")
        ax_i.plot(current, self.pressure_bar, lw=0.9, label="simulated")
        ax_t.set(xlabel="time (s)", ylabel="clutch pressure (bar)", title=self.trace_name)
        ax_i.set(xlabel="nominal current (mA)", ylabel="clutch pressure (bar)")
        for ax in axes:
            ax.grid(alpha=0.3)
            ax.legend(loc="upper left")
        return fig

    def _check_same_grid(self, measured) -> None:
        """Refuse a measured trace whose samples are not this result's (ModelError)."""
        t = np.asarray(measured.time_s)
        if t.shape == self.time_s.shape and np.allclose(t, self.time_s, rtol=0.0, atol=1e-9):
            return
        span = f"{t[0]:.6g}–{t[-1]:.6g} s" if t.size else "no samples"
        mine = f"{self.time_s[0]:.6g}–{self.time_s[-1]:.6g} s" if len(self.time_s) else "none"
        raise ModelError(
            f"plot: the measured trace {measured.name!r} ({t.size} samples, {span}) is not on "
            f"the time grid of the simulated trace {self.trace_name!r} ({len(self.time_s)} "
            f"samples, {mine}); pass the trace that was simulated (a slice: slice the "
            "measured trace the same way, trace.slice_time(t0, t1))"
        )
