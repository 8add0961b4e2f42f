"""Staged start of the physics fit: the static characteristic and the latch before the dynamics.

A circuit that is not clutchlab's own can sit far from the datasheet model: its
characteristic has another gain and threshold, its latch snaps at other currents.
Started from the datasheet, the full fit then spends its iterations (and its time
budget) walking the latch snap across the data, where the cost is nearly flat between
samples and steep at them. The staged start gives it a start near the data first:

1. **latch currents from the data**: on the quasi-static experiments (the slowest ramp
   rate of the training set) the currents where the dither-period-mean pressure snaps
   to line pressure (rising) and leaves it (falling);
2. **static stage**: the static parameters (VFS force curve and preload, regulator
   spring offset, a monotone force correction when switched on) fitted on the rising,
   regulated branch of at most two quasi-static experiments, up to just before the
   latch snaps; heavily decimated, a few iterations;
3. **latch thresholds**: the model's pilot pressure at the measured latch currents
   (simulated with the static stage's parameters) gives the latch-on and latch-off
   pilot pressures; set directly with ``latch_free_thresholds``, or as the spring
   preload and rate of the datasheet valve, within their bounds.

Only training experiments are used (the fit's own), and every stage is optional:
a stage that finds nothing to work on (no latch in the data, no static parameter free)
is skipped and says so.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from ...data import Trace, dither_period_mean, dither_period_samples
from ...errors import FitError, FitWarning
from ..model import CircuitModel
from ..parameters import ParameterSet
from ..settings import SimulationSettings
from ..simulate import simulate
from .settings import FitSettings

__all__ = [
    "STATIC_PARAMETERS",
    "StagedStart",
    "free_latch_structure",
    "measured_latch_indices",
    "quasi_static_traces",
    "staged_start",
]

#: Parameters the static stage may move (when free): the static characteristic.
STATIC_PARAMETERS: tuple[str, ...] = (
    "vfs_K_m",
    "vfs_i_knee",
    "vfs_F_pre",
    "reg_F0",
    "mspl_d1",
    "mspl_d2",
    "mspl_d3",
    "mspl_d4",
)

#: Line pressure (bar) assumed when a trace does not log it (DESIGN §3).
_LINE_DEFAULT_BAR = 17.7
#: A latched clutch is within this of line pressure (bar).
_LATCH_MARGIN_BAR = 1.0
#: The static stage ends this long before the latch snaps (s).
_BEFORE_SNAP_S = 0.5


@dataclass
class StagedStart:
    """What the staged start did (for the fit's log and report).

    Attributes
    ----------
    values : dict of str to float
        Start values it changed (engineering units).
    latch_currents_mA : dict of str to (float, float)
        Measured latch-on / latch-off nominal current (mA) per quasi-static experiment.
    thresholds_bar : (float, float) or None
        Latch-on / latch-off pilot pressure (bar) read off the model at those currents.
    static_experiments : list of str
        Experiments of the static stage.
    latch_tie_violated : bool
        The measured thresholds do not fit the datasheet latch: with its areas and
        stroke, the spring rate they need lies outside its bounds (a latch-off far below
        ``A1/A2 ·`` latch-on, or too close to it).
    wall_s : float
        Wall time of the staged start (s).
    notes : list of str
        Stages skipped or clipped, and why.
    """

    values: dict[str, float] = field(default_factory=dict)
    latch_currents_mA: dict[str, tuple[float, float]] = field(default_factory=dict)
    thresholds_bar: tuple[float, float] | None = None
    static_experiments: list[str] = field(default_factory=list)
    latch_tie_violated: bool = False
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """One paragraph for the CLI and the report."""
        parts = [f"staged start ({self.wall_s:.1f} s)"]
        if self.static_experiments:
            parts.append(f"static stage on {', '.join(self.static_experiments)}")
        if self.thresholds_bar is not None:
            on, off = self.thresholds_bar
            parts.append(f"latch pilot thresholds {on:.2f} / {off:.2f} bar from the data")
        if self.values:
            parts.append(
                "start: " + ", ".join(f"{k}={v:.4g}" for k, v in sorted(self.values.items()))
            )
        return "; ".join(parts + self.notes)


def _current(trace: Trace) -> np.ndarray:
    return trace.get("current_cmd_mA") if trace.has("current_cmd_mA") else trace.get("current_mA")


def _period_mean(trace: Trace, x: np.ndarray) -> np.ndarray:
    return dither_period_mean(np.asarray(x, float), dither_period_samples(trace))


def quasi_static_traces(traces: list[Trace]) -> list[Trace]:
    """The training experiments of the slowest ramp rate (within 1.5× of it).

    The ramp rate of an experiment is the 95th percentile of |dI/dt| of its
    dither-period-mean current (mA/s), so the rate is the data's, not a label's.
    """
    rates = []
    for tr in traces:
        i = _period_mean(tr, _current(tr))
        rates.append(float(np.percentile(np.abs(np.gradient(i, tr.time_s)), 95)))
    lo = min(rates)
    return [tr for tr, r in zip(traces, rates, strict=True) if r <= 1.5 * lo]


def measured_latch_indices(trace: Trace) -> tuple[int, int] | None:
    """Sample indices where the pressure snaps to line (rising) and leaves it (falling).

    ``None`` when the experiment never reaches line pressure, or reaches it only on one
    branch.
    """
    i = _period_mean(trace, _current(trace))
    p = _period_mean(trace, trace.get("clutch_pressure_bar"))
    line = (
        _period_mean(trace, trace.get("line_pressure_bar"))
        if trace.has("line_pressure_bar")
        else np.full(len(p), _LINE_DEFAULT_BAR)
    )
    di = np.gradient(i)
    near = p > line - _LATCH_MARGIN_BAR
    rising = np.flatnonzero((di > 0) & near)
    falling = np.flatnonzero((di < 0) & near)
    if not len(rising) or not len(falling):
        return None
    return int(rising[0]), int(falling[-1])


def _static_stage(model, start, traces, latch, settings, free, budget_s, info):
    """Fit the free static parameters on the rising regulated branch; returns parameters."""
    static_free = tuple(n for n in free if n in STATIC_PARAMETERS)
    if not static_free:
        info.notes.append("no static parameter free: static stage skipped")
        return start
    pieces = []
    for tr in traces[:2]:
        k = latch.get(tr.name)
        t_end = tr.time_s[k[0]] - _BEFORE_SNAP_S if k else tr.time_s[int(np.argmax(_current(tr)))]
        if t_end - tr.time_s[0] > 2.0:
            pieces.append(tr.slice_time(None, t_end))
    if not pieces:
        info.notes.append("no regulated rising branch long enough: static stage skipped")
        return start
    from .fitter import PhysicsFitter  # the stage is itself a (small) fit

    stage = replace(
        settings,
        free=static_free,
        per_experiment=(),
        bounds={k: v for k, v in settings.bounds.items() if k in static_free},
        decimate=max(settings.decimate, 50),
        max_iter=settings.static_max_iter,
        prefit_samples=None,
        time_limit_s=budget_s,
        multistart=0,
        progress=False,
        strict=False,
        staged_start=False,
        ipopt_options={"acceptable_tol": 0.1, "acceptable_obj_change_tol": 1e-3},
    )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            fitted = PhysicsFitter(model, stage, start).fit(pieces).params_
    except FitError as exc:
        info.notes.append(f"static stage kept the start ({exc})")
        return start
    info.static_experiments = [p.name for p in pieces]
    return fitted


def _clip(start: ParameterSet, name: str, value: float, bounds) -> float:
    spec = start.spec(name)
    lo, hi = bounds.get(name, (spec.lower, spec.upper))
    return float(min(max(value, lo), hi))


def _threshold_stage(model, start, traces, latch, settings, free, info):
    """Latch thresholds from the model's pilot pressure at the measured latch currents."""
    names = {p.name for p in model.parameters}
    free_thr = "lthr_p_on" in names and {"lthr_p_on", "lthr_p_off"} <= set(free)
    free_spring = {"latch_F0", "latch_k"} <= set(free) and "lthr_p_on" not in names
    if not (free_thr or free_spring):
        info.notes.append("latch parameters not free: thresholds left at the start")
        return start
    on, off = [], []
    sim = SimulationSettings(substeps=settings.substeps)
    for tr in traces:
        k = latch.get(tr.name)
        if k is None:
            continue
        pilot = simulate(model, start, tr, sim).outputs.get("pilot_pressure_bar")
        if pilot is None:
            info.notes.append("the model has no pilot-pressure output: thresholds left")
            return start
        pm = _period_mean(tr, pilot)
        on.append(pm[k[0]])
        off.append(pm[k[1]])
    if not on:
        info.notes.append("no latch snap in the quasi-static data: thresholds left")
        return start
    p_on, p_off = float(np.median(on)), float(np.median(off))
    info.thresholds_bar = (p_on, p_off)
    if free_thr:
        values = {
            "lthr_p_on": _clip(start, "lthr_p_on", p_on, settings.bounds),
            "lthr_p_off": _clip(start, "lthr_p_off", p_off, settings.bounds),
        }
    else:
        a1 = math.pi / 4.0 * (start["latch_d1"] * 1e-3) ** 2
        a2 = math.pi / 4.0 * (start["latch_d2"] * 1e-3) ** 2
        f0 = p_on * 1e5 * a1
        k = (p_off * 1e5 * a2 - f0) / (start["latch_stroke"] * 1e-3) / 1e3
        values = {
            "latch_F0": _clip(start, "latch_F0", f0, settings.bounds),
            "latch_k": _clip(start, "latch_k", k, settings.bounds),
        }
        if values["latch_k"] != k:
            info.latch_tie_violated = True
            info.notes.append(
                f"the datasheet latch cannot release at {p_off:.2f} bar with latch-on at "
                f"{p_on:.2f} bar (its area ratio ties them; latch_k would be {k:.3g} N/mm)"
            )
    return start.replace(**values)


def staged_start(
    model: CircuitModel,
    traces: list[Trace],
    settings: FitSettings,
    start: ParameterSet,
    free: tuple[str, ...],
    budget_s: float,
) -> tuple[ParameterSet, StagedStart]:
    """Run the staged start on the training experiments; returns the start and its record.

    Parameters
    ----------
    model : CircuitModel
        Structure being fitted.
    traces : list of Trace
        Training experiments (never the test ramp).
    settings : FitSettings
        The fit's settings (bounds, substeps, workers, static-stage iteration limit).
    start : ParameterSet
        Start values before the staged start (datasheet or user's).
    free : tuple of str
        The fit's free parameters; only these move.
    budget_s : float
        Wall time the static stage may use (s).
    """
    t0 = time.perf_counter()
    info = StagedStart()
    qs = quasi_static_traces(traces)
    latch = {}
    for tr in qs:
        k = measured_latch_indices(tr)
        if k is not None:
            latch[tr.name] = k
            i = _period_mean(tr, _current(tr))
            info.latch_currents_mA[tr.name] = (float(i[k[0]]), float(i[k[1]]))
    params = _static_stage(model, start, qs, latch, settings, free, budget_s, info)
    params = _threshold_stage(model, params, qs[:3], latch, settings, free, info)
    info.values = {n: params[n] for n in free if params[n] != start[n]}
    info.wall_s = time.perf_counter() - t0
    return params, info


def free_latch_structure(
    model: CircuitModel, start: ParameterSet, info: StagedStart
) -> tuple[CircuitModel, ParameterSet]:
    """The model with ``latch_free_thresholds`` and a start at the measured thresholds.

    Used when the staged start found the datasheet latch's area-ratio tie violated by
    the training data: the free-threshold law has the same number of parameters (two
    thresholds for preload and rate), without the tie. Every other start value is kept.
    """
    free_model = model.with_effects("latch_free_thresholds")
    names = {p.name for p in free_model.parameters}
    values = {n: start[n] for n in start if n in names}
    if info.thresholds_bar is not None:
        on, off = info.thresholds_bar
        spec_on = free_model.default_params().spec("lthr_p_on")
        spec_off = free_model.default_params().spec("lthr_p_off")
        values["lthr_p_on"] = float(min(max(on, spec_on.lower), spec_on.upper))
        values["lthr_p_off"] = float(min(max(off, spec_off.lower), spec_off.upper))
    info.notes.append(
        "structure: latch_free_thresholds (same parameter count as the datasheet latch's "
        "preload and rate, without the area-ratio tie the training data violate)"
    )
    return free_model, free_model.params(**values)
