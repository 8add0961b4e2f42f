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
4. **latch snaps matched**: the threshold reading assumes the latch switches where its
   static force balance says; the model's latch valve moves, so it snaps a little later.
   A few simulations of the quasi-static experiments move the two latch parameters (in
   pilot-pressure coordinates, per-coordinate secant steps) until the model snaps at the
   measured currents (:func:`match_latch_snaps`). This runs after the fit has chosen its
   latch and lag structure, on the structure it will fit.
5. **lag signature**: two time constants read off the fastest and the slowest
   training ramps — how much the regulated band widens with the pressure rate
   (``τ_band``) and how far the latch currents move with the current rate
   (``τ_latch``) — for the data and for the model at the staged start. The model's
   one pilot lag scales both together; when the data's ``τ_band / τ_latch`` is well
   above the model's, the regulated branch lags through a path the latch does not
   see, and the fit adds ``reg_pilot_lag`` (:func:`lag_signature`).

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

from ...data import (
    LINE_PRESSURE_BAR,
    Trace,
    dither_period_mean,
    dither_period_samples,
    ramp_rate_mA_s,
)
from ...errors import FitError, FitWarning
from ..model import CircuitModel
from ..parameters import ParameterSet, quiet_design_checks
from ..settings import SimulationSettings
from ..simulate import simulate
from .sensitivity import compile_fit_code
from .settings import FitSettings

__all__ = [
    "STATIC_PARAMETERS",
    "StagedStart",
    "fastest_traces",
    "free_latch_structure",
    "lag_signature",
    "latch_port_structure",
    "latches_where_data_do_not",
    "match_latch_snaps",
    "measured_latch_indices",
    "measured_thresholds",
    "never_latches",
    "quasi_static_traces",
    "ramp_rate",
    "regulated_band",
    "regulator_lag_structure",
    "snap_offsets_each",
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

#: A latched clutch is within this of line pressure (bar).
_LATCH_MARGIN_BAR = 1.0
#: The static stage ends this long before the latch snaps (s).
_BEFORE_SNAP_S = 0.5
#: Simulations the latch-snap matching may spend (each: two quasi-static experiments).
_MATCH_ROUNDS = 7
#: Finite-difference step (bar) of the matching's first Jacobian, and its largest step.
_MATCH_FD_BAR = 0.1
_MATCH_STEP_BAR = 1.0
#: Times the matching halves a step that would put a latch parameter on its bound or does
#: not lower the offsets, before it ends (session 59: stopping at the first such step left
#: the snaps unmatched, 25-86 mA off, on 4 of 20 datasets).
_MATCH_HALVINGS = 4
#: Snap currents within this of the measured ones (mA, worse of latch-on and -off) end it.
_MATCH_TOL_MA = 1.0


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
    lag_signature : dict of str to float
        ``tau_band_ms`` and ``tau_latch_ms`` of the data and of the start model
        (keys prefixed ``data_`` / ``model_``), when measurable.
    regulator_lag_ms : float or None
        Start time constant (ms) of ``reg_pilot_lag`` when the signature asks for it.
    latch_port : dict of str to float
        When the signature asked for the lag: the fast ramps' worse latch-snap offset (mA)
        of the feedback-exhaust latch (``exhaust_fast_mA``) and of the line-select latch
        (``line_select_fast_mA``), each matched on the slow ramps
        (:func:`latch_port_structure`).
    latch_match_mA : dict of str to float
        Latch-snap matching: the model's latch-on / latch-off current minus the measured
        one (mA, median over the quasi-static experiments) before (``on_before``,
        ``off_before``) and after (``on_after``, ``off_after``), and ``simulations``.
    latch_jacobian : list of list of float or None
        The matching's last Jacobian: d(latch-on, latch-off offset, mA) / d(latch-on,
        latch-off pilot threshold, bar) (for :func:`~clutchlab.physics.fit.latch_band.
        latch_band_structure`).
    latch_band : dict of str to float
        The latch band stage's record (:func:`~clutchlab.physics.fit.latch_band.
        latch_band_structure`), when it ran.
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
    lag_signature: dict[str, float] = field(default_factory=dict)
    regulator_lag_ms: float | None = None
    latch_port: dict[str, float] = field(default_factory=dict)
    static_experiments: list[str] = field(default_factory=list)
    latch_match_mA: dict[str, float] = field(default_factory=dict)
    latch_jacobian: list[list[float]] | None = None
    latch_band: dict[str, float] = field(default_factory=dict)
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
        if self.latch_match_mA:
            m = self.latch_match_mA
            parts.append(
                "latch snaps matched to the data (model − measured, on / off: "
                f"{m['on_before']:+.1f} / {m['off_before']:+.1f} → "
                f"{m['on_after']:+.1f} / {m['off_after']:+.1f} mA, "
                f"{int(m['simulations'])} simulations)"
            )
        if self.lag_signature:
            sig = self.lag_signature
            parts.append(
                "lag signature τ_band / τ_latch: data "
                f"{sig['data_tau_band_ms']:.0f} / {sig['data_tau_latch_ms']:.0f} ms, model "
                f"{sig['model_tau_band_ms']:.0f} / {sig['model_tau_latch_ms']:.0f} ms"
            )
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
    rates = [ramp_rate(tr) for tr in traces]
    lo = min(rates)
    return [tr for tr, r in zip(traces, rates, strict=True) if r <= 1.5 * lo]


def fastest_traces(traces: list[Trace]) -> list[Trace]:
    """The training experiments of the fastest ramp rate (within 1.5× of it)."""
    rates = [ramp_rate(tr) for tr in traces]
    hi = max(rates)
    return [tr for tr, r in zip(traces, rates, strict=True) if r >= hi / 1.5]


def ramp_rate(trace: Trace) -> float:
    """Ramp rate (mA/s): the 95th percentile of |dI/dt| of the period-mean current
    (:func:`~clutchlab.data.ramps.ramp_rate_mA_s`; 0 when it cannot be measured)."""
    return ramp_rate_mA_s(trace) or 0.0


def _line(trace: Trace, n: int) -> np.ndarray:
    if trace.has("line_pressure_bar"):
        return _period_mean(trace, trace.get("line_pressure_bar"))
    return np.full(n, LINE_PRESSURE_BAR)


def regulated_band(trace: Trace, pressure: np.ndarray | None = None) -> tuple[float, float] | None:
    """Width of the regulated hysteresis band and the pressure rate on it.

    Over the currents where both the rising and the falling branch regulate (above
    prime + 1 bar, below line − 1 bar), on dither-period means: the median of falling
    minus rising pressure (bar) at equal current, and the median |dp/dt| (bar/s).

    Parameters
    ----------
    trace : Trace
        One ramp experiment (current up, then down).
    pressure : ndarray, optional
        Clutch pressure (bar) to measure instead of the trace's (a model's prediction).

    Returns
    -------
    (float, float) or None
        Width (bar) and rate (bar/s); ``None`` when the branches share no regulated
        current span of at least 50 mA.
    """
    i = _period_mean(trace, _current(trace))
    p_raw = trace.get("clutch_pressure_bar") if pressure is None else pressure
    p = _period_mean(trace, p_raw)
    line = _line(trace, len(p))
    prime = (
        _period_mean(trace, trace.get("prime_pressure_bar"))
        if trace.has("prime_pressure_bar")
        else np.zeros(len(p))
    )
    top = int(np.argmax(i))
    ok = (p > prime + 1.0) & (p < line - _LATCH_MARGIN_BAR)
    branches = []
    for sl in (slice(0, top), slice(top, len(i))):
        m = np.flatnonzero(ok[sl]) + (sl.start or 0)
        if len(m) < 10:
            return None
        order = np.argsort(i[m])
        branches.append((i[m][order], p[m][order], m))
    lo = max(b[0][0] for b in branches)
    hi = min(b[0][-1] for b in branches)
    if hi - lo < 50.0:
        return None
    grid = np.linspace(lo, hi, 50)
    rise, fall = (np.interp(grid, b[0], b[1]) for b in branches)
    dpdt = np.abs(np.gradient(p, trace.time_s))
    band = np.concatenate([b[2][(i[b[2]] >= lo) & (i[b[2]] <= hi)] for b in branches])
    return float(np.median(fall - rise)), float(np.median(dpdt[band]))


def _near_line(trace: Trace) -> tuple[np.ndarray, np.ndarray]:
    """The period-mean current's slope (mA per sample) and where the period-mean clutch
    pressure is within the latch margin of line pressure (latched)."""
    i = _period_mean(trace, _current(trace))
    p = _period_mean(trace, trace.get("clutch_pressure_bar"))
    return np.gradient(i), p > _line(trace, len(p)) - _LATCH_MARGIN_BAR


def measured_latch_indices(trace: Trace) -> tuple[int, int] | None:
    """Sample indices where the pressure snaps to line (rising) and leaves it (falling).

    ``None`` when the experiment never reaches line pressure, or reaches it only on one
    branch.
    """
    di, near = _near_line(trace)
    rising = np.flatnonzero((di > 0) & near)
    falling = np.flatnonzero((di < 0) & near)
    if not len(rising) or not len(falling):
        return None
    return int(rising[0]), int(falling[-1])


def _predicted(model, params, trace: Trace, sim: SimulationSettings) -> Trace:
    """``trace`` with the model's clutch pressure (bar) in place of the measured one."""
    y = simulate(model, params, trace, sim).outputs["clutch_pressure_bar"]
    return trace.with_signals(clutch_pressure_bar=y)


def never_latches(trace: Trace) -> bool:
    """Whether the experiment's clutch pressure never comes near line pressure (within
    the latch margin, dither-period means): the circuit does not latch on it at all."""
    return not np.any(_near_line(trace)[1])


def latches_where_data_do_not(
    model: CircuitModel, params: ParameterSet, traces: list[Trace], substeps: int = 2
) -> list[str]:
    """Experiments on which the measured clutch pressure never reaches line pressure but the
    model's does (:func:`never_latches` on each).

    A latch that the dither keeps from tripping (one that needs its pilot beyond a threshold
    for a dwell time longer than the dither's trough leaves it, or whose pilot passage
    filters the dither) never latches on a large, slow dither; clutchlab's latch switches
    on the dithered pilot and does. One simulation per experiment that never latches.

    Parameters
    ----------
    model, params : CircuitModel, ParameterSet
        The (fitted) model and its values.
    traces : list of Trace
        Experiments (training ones, for a fit's report).
    substeps : int
        Integrator substeps.

    Returns
    -------
    list of str
        Their names, in the order given.
    """
    sim = SimulationSettings(substeps=substeps, out_of_range="ignore")
    found = []
    for tr in traces:
        if never_latches(tr) and not never_latches(_predicted(model, params, tr, sim)):
            found.append(tr.name)
    return found


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

    # Its code is compiled (or loaded) before its clock starts. On an empty compile cache,
    # with the main stages' code compiling beside it, the time limit would otherwise stop
    # it earlier than on a warm cache, and the fit would start from another point (single
    # shooting, the default; multiple-shooting segments compile their code on first use).
    compile_fit_code(model, pieces, settings.substeps, settings.drive, len(static_free))
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
            result = PhysicsFitter(model, stage, start).fit(pieces).result_
    except FitError as exc:
        info.notes.append(f"static stage kept the start ({exc})")
        return start
    if "WallTime" in result.status:
        info.notes.append(
            f"static stage stopped at its time limit ({budget_s:.0f} s) after "
            f"{result.iterations} iterations: on a faster or idler machine it would go further"
        )
    fitted = result.params()
    info.static_experiments = [p.name for p in pieces]
    return fitted


def _clip(start: ParameterSet, name: str, value: float, bounds) -> float:
    spec = start.spec(name)
    lo, hi = bounds.get(name, (spec.lower, spec.upper))
    return float(min(max(value, lo), hi))


def measured_thresholds(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    latch: dict[str, tuple[int, int]] | None = None,
    substeps: int = 8,
) -> tuple[float, float] | str:
    """Latch-on / latch-off pilot pressures (bar) at the data's latch snaps.

    The model's pilot pressure (period mean), simulated at ``params``, at the samples where
    the measured pressure snaps to line and leaves it (:func:`measured_latch_indices`),
    median over ``traces``: the thresholds a latch would need to switch where the data do,
    given the model's pilot.

    Parameters
    ----------
    model, params : CircuitModel, ParameterSet
        The model and its parameters.
    traces : list of Trace
        Experiments to read the snaps from (the quasi-static ones are best).
    latch : dict, optional
        Experiment name -> (latch-on, latch-off) sample indices; measured when omitted.
    substeps : int
        Integrator substeps of the simulations.

    Returns
    -------
    (float, float) or str
        The thresholds, or why there are none.
    """
    on, off = [], []
    sim = SimulationSettings(substeps=substeps, out_of_range="ignore")
    for tr in traces:
        k = latch.get(tr.name) if latch is not None else measured_latch_indices(tr)
        if k is None:
            continue
        pilot = simulate(model, params, tr, sim).outputs.get("pilot_pressure_bar")
        if pilot is None:
            return "the model has no pilot-pressure output"
        pm = _period_mean(tr, pilot)
        on.append(pm[k[0]])
        off.append(pm[k[1]])
    if not on:
        return "no latch snap in the data"
    return float(np.median(on)), float(np.median(off))


def _latch_law(model: CircuitModel, free) -> str | None:
    """Which latch parameters the fit moves: ``"thresholds"`` (``latch_free_thresholds``),
    ``"spring"`` (the datasheet valve's preload and rate) or None (neither free)."""
    names = {p.name for p in model.parameters}
    if "lthr_p_on" in names:
        return "thresholds" if {"lthr_p_on", "lthr_p_off"} <= set(free) else None
    return "spring" if {"latch_F0", "latch_k"} <= set(free) else None


def _latch_areas(params: ParameterSet) -> tuple[float, float]:
    """The datasheet latch's pilot (latch-on) and differential (latch-off) areas (m²)."""
    return tuple(math.pi / 4.0 * (params[d] * 1e-3) ** 2 for d in ("latch_d1", "latch_d2"))


def _measured_latches(traces: list[Trace]) -> dict[str, tuple[int, int]]:
    """Experiment name -> measured (latch-on, latch-off) sample indices, where both exist."""
    return {tr.name: k for tr in traces if (k := measured_latch_indices(tr)) is not None}


def _spring_from_thresholds(params: ParameterSet, p_on: float, p_off: float) -> tuple[float, float]:
    """Datasheet latch preload (N) and rate (N/mm) that switch at pilot pressures ``p_on``
    and ``p_off`` (bar) by its static force balance (areas and stroke from ``params``)."""
    a1, a2 = _latch_areas(params)
    f0 = p_on * 1e5 * a1
    return f0, (p_off * 1e5 * a2 - f0) / (params["latch_stroke"] * 1e-3) / 1e3


def _thresholds_from_spring(params: ParameterSet) -> tuple[float, float]:
    """Inverse of :func:`_spring_from_thresholds` (bar)."""
    a1, a2 = _latch_areas(params)
    f0, k = params["latch_F0"], params["latch_k"]
    return f0 / (1e5 * a1), (f0 + k * params["latch_stroke"]) / (1e5 * a2)


def _thresholds_of(law: str, params: ParameterSet) -> np.ndarray:
    """Latch-on / latch-off pilot pressures (bar) of ``params``' latch."""
    if law == "thresholds":
        return np.array([params["lthr_p_on"], params["lthr_p_off"]])
    return np.array(_thresholds_from_spring(params))


def _with_thresholds(law: str, params: ParameterSet, p_on: float, p_off: float, bounds):
    """``params`` with the latch set to switch at ``p_on`` / ``p_off`` (bar), clipped to the
    bounds; and the names of the parameters that needed the clip."""
    if law == "thresholds":
        values = {"lthr_p_on": p_on, "lthr_p_off": p_off}
    else:
        f0, k = _spring_from_thresholds(params, p_on, p_off)
        values = {"latch_F0": f0, "latch_k": k}
    kept = {n: _clip(params, n, v, bounds) for n, v in values.items()}
    return params.replace(**kept), {n for n in values if kept[n] != values[n]}


def _threshold_stage(model, start, traces, latch, settings, free, info):
    """Latch thresholds from the model's pilot pressure at the measured latch currents."""
    law = _latch_law(model, free)
    if law is None:
        info.notes.append("latch parameters not free: thresholds left at the start")
        return start
    found = measured_thresholds(model, start, traces, latch, settings.substeps)
    if isinstance(found, str):
        info.notes.append(f"{found}: thresholds left at the start")
        return start
    p_on, p_off = found
    info.thresholds_bar = (p_on, p_off)
    params, clipped = _with_thresholds(law, start, p_on, p_off, settings.bounds)
    if "latch_k" in clipped:
        info.latch_tie_violated = True
        k = _spring_from_thresholds(start, p_on, p_off)[1]
        info.notes.append(
            f"the datasheet latch cannot release at {p_off:.2f} bar with latch-on at "
            f"{p_on:.2f} bar (its area ratio ties them; latch_k would be {k:.3g} N/mm)"
        )
    return params


def snap_offsets_each(model, params, traces, latch, substeps) -> np.ndarray | None:
    """The model's latch-on and latch-off current minus the measured one (mA), one row per
    trace (``latch``: measured indices by name); None when the model does not snap on both
    branches of every trace."""
    rows = []
    sim = SimulationSettings(substeps=substeps, out_of_range="ignore")
    for tr in traces:
        own = measured_latch_indices(_predicted(model, params, tr, sim))
        if own is None:
            return None
        i, k = _period_mean(tr, _current(tr)), latch[tr.name]
        rows.append([i[own[0]] - i[k[0]], i[own[1]] - i[k[1]]])
    return np.asarray(rows)


def _snap_offsets(model, params, traces, latch, substeps) -> np.ndarray | None:
    """:func:`snap_offsets_each`, median over ``traces``."""
    rows = snap_offsets_each(model, params, traces, latch, substeps)
    return None if rows is None else np.median(rows, axis=0)


@quiet_design_checks  # its probes are not the user's values
def match_latch_snaps(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
    info: StagedStart,
    budget_s: float = math.inf,
) -> ParameterSet:
    """Move the latch parameters until the model snaps at the measured latch currents.

    On the (at most two) quasi-static training experiments with a measured snap, the model's
    latch-on and latch-off currents are compared with the measured ones. The two latch
    parameters, in pilot-pressure coordinates (the thresholds; the datasheet latch through
    its force balance), take Newton steps on that 2 × 2 system: a finite-difference Jacobian,
    then Broyden updates, steps of at most ``_MATCH_STEP_BAR``, for at most
    ``_MATCH_ROUNDS`` simulations in all or until both snaps are within ``_MATCH_TOL_MA``.
    A step that would put a latch parameter on its bound, or that does not lower the
    offsets, is halved (up to ``_MATCH_HALVINGS`` times in a row) before the matching ends.
    The best point is kept; the start when nothing improves it or when the model does not
    snap on both branches. Nothing is matched without a static stage (``info``) — the
    pilot pressure is then not known well enough. No new round starts after ``budget_s``
    (compiling excluded).

    Parameters
    ----------
    model : CircuitModel
        Structure the fit will use (after its latch and lag choices).
    params : ParameterSet
        Start parameters (after the staged start).
    traces : list of Trace
        Training experiments (the quasi-static ones are used).
    free : tuple of str
        The fit's free parameters; the latch is matched only when its two are free.
    settings : FitSettings
        Bounds and integrator substeps.
    info : StagedStart
        Record of the staged start; ``values``, ``latch_match_mA`` and ``notes`` are
        filled in.
    budget_s : float
        Wall time (s) after which no further simulation round starts, counted from the end
        of the first simulation (which may compile the model's code).

    Returns
    -------
    ParameterSet
        ``params`` with the matched latch parameters.
    """
    law = _latch_law(model, free)
    if law is None:
        return params
    if not info.static_experiments:
        # Without a fitted static characteristic (no quasi-static rising branch) the latch
        # would absorb the characteristic's error and the ramp's lag.
        info.notes.append("no static stage: latch snaps not matched")
        return params
    qs = quasi_static_traces(traces)
    latch = _measured_latches(qs)
    used = [tr for tr in qs if tr.name in latch][:2]
    if not used:
        return params
    n_sim = 0

    def offsets(p):
        nonlocal n_sim
        n_sim += 1
        return _snap_offsets(model, p, used, latch, settings.substeps)

    def at(x):
        p, clipped = _with_thresholds(law, params, *x, settings.bounds)
        return p, _thresholds_of(law, p), bool(clipped)

    x = _thresholds_of(law, params)
    f = offsets(params)
    t0 = time.perf_counter()  # after the first simulation, which may compile the model's code
    if f is None:
        info.notes.append("the start model does not snap on both branches: latch not matched")
        return params
    first, best = f, (float(np.max(np.abs(f))), params, f)
    jac = np.zeros((2, 2))
    for j in range(2):  # finite differences
        p_j, x_j, clipped = at(x + _MATCH_FD_BAR * np.eye(2)[j])
        f_j = None if clipped else offsets(p_j)
        if f_j is None:
            info.notes.append(
                "latch-snap matching: no snap at a perturbed threshold, or a bound; not matched"
            )
            return params
        jac[:, j] = (f_j - f) / (x_j[j] - x[j])
    halved = 0
    while best[0] > _MATCH_TOL_MA and n_sim < _MATCH_ROUNDS and time.perf_counter() - t0 < budget_s:
        dx = np.linalg.lstsq(jac, -f, rcond=None)[0]
        dx *= min(1.0, _MATCH_STEP_BAR / max(float(np.max(np.abs(dx))), 1e-12)) / 2**halved
        p_new, x_new, clipped = at(x + dx)
        # a latch on its bounds would be absorbing another error: a shorter step, no simulation
        f_new = None if clipped else offsets(p_new)
        if f_new is not None:  # the Jacobian learns from every simulated step
            dx = x_new - x
            jac += np.outer((f_new - f) - jac @ dx, dx) / max(float(dx @ dx), 1e-12)
        if f_new is None or float(np.max(np.abs(f_new))) >= best[0]:
            halved += 1
            if halved > _MATCH_HALVINGS:
                break
            continue
        halved = 0
        x, f = x_new, f_new
        best = (float(np.max(np.abs(f))), p_new, f)
    info.values.update({n: best[1][n] for n in free if best[1][n] != params[n]})
    info.latch_jacobian = jac.tolist()
    info.latch_match_mA = {
        "on_before": float(first[0]),
        "off_before": float(first[1]),
        "on_after": float(best[2][0]),
        "off_after": float(best[2][1]),
        "simulations": float(n_sim),
    }
    return best[1]


#: The data's τ_band / τ_latch must exceed the model's by this factor to add the lag.
LAG_RATIO_MARGIN = 1.3
#: Shortest regulator lag (ms) worth a state of its own.
_MIN_REG_LAG_MS = 10.0


def lag_signature(
    fast: list[Trace],
    slow: list[Trace],
    pressures: dict[str, np.ndarray] | None = None,
) -> dict[str, float] | None:
    """Two time constants of a circuit, read off a fast and a slow ramp (median over each).

    - ``tau_band_ms``: the regulated band's widening with the pressure rate,
      ``(W_fast − W_slow) / (2 (ṗ_fast − ṗ_slow))`` with ``W`` the band width (bar) and
      ``ṗ`` the pressure rate on it (bar/s) (:func:`regulated_band`); a first-order lag
      ``τ`` in the regulated path gives ``τ``.
    - ``tau_latch_ms``: the latch currents' shift with the current rate, the mean over
      latch-on (later when faster) and latch-off (earlier when faster) of
      ``Δi / (İ_fast − İ_slow)``; a first-order lag ``τ`` before the latch gives ``τ``.

    Parameters
    ----------
    fast, slow : list of Trace
        Experiments at the fastest and the slowest ramp rate.
    pressures : dict of str to ndarray, optional
        Clutch pressure (bar) per experiment name to use in place of the measured one
        (a model's prediction).

    Returns
    -------
    dict or None
        ``{"tau_band_ms", "tau_latch_ms"}``; ``None`` when either is not measurable
        (no shared regulated span, no latch snap on both branches, equal rates).
    """
    rows = []
    for group in (fast, slow):
        vals = []
        for tr in group:
            p = None if pressures is None else pressures[tr.name]
            band = regulated_band(tr, p)
            k = measured_latch_indices(tr if p is None else tr.with_signals(clutch_pressure_bar=p))
            if band is None or k is None:
                continue
            i = _period_mean(tr, _current(tr))
            vals.append((ramp_rate(tr), *band, i[k[0]], i[k[1]]))
        if not vals:
            return None
        rows.append(np.median(np.array(vals), axis=0))
    (rf, wf, pf, onf, offf), (rs, ws, ps, ons, offs) = rows
    if rf <= 1.5 * rs or pf <= ps:
        return None
    tau_band = (wf - ws) / (2.0 * (pf - ps))
    tau_latch = 0.5 * ((onf - ons) + (offs - offf)) / (rf - rs)
    return {"tau_band_ms": 1e3 * tau_band, "tau_latch_ms": 1e3 * tau_latch}


def _lag_stage(model, params, traces, settings, info) -> None:
    """Compare the data's lag signature with the model's; ask for ``reg_pilot_lag``."""
    fast, slow = fastest_traces(traces)[:2], quasi_static_traces(traces)[:2]
    if fast[0] is slow[0]:
        info.notes.append("one ramp rate only: lag signature not measured")
        return
    data = lag_signature(fast, slow)
    sim = SimulationSettings(substeps=settings.substeps, out_of_range="ignore")
    pred = {
        tr.name: simulate(model, params, tr, sim).outputs["clutch_pressure_bar"]
        for tr in fast + slow
    }
    mod = lag_signature(fast, slow, pred)
    if data is None or mod is None:
        info.notes.append("lag signature not measurable (no regulated band or latch snap)")
        return
    info.lag_signature = {
        **{f"data_{k}": v for k, v in data.items()},
        **{f"model_{k}": v for k, v in mod.items()},
    }
    d_band, d_latch = data["tau_band_ms"], max(data["tau_latch_ms"], 1.0)
    m_band, m_latch = mod["tau_band_ms"], max(mod["tau_latch_ms"], 1.0)
    ratio_data, ratio_model = d_band / d_latch, m_band / m_latch
    if ratio_data <= LAG_RATIO_MARGIN * ratio_model:
        return
    # With the pilot lag matched to the latch's delay, the model's band lag is
    # ratio_model × τ_latch; the regulator lag supplies the rest.
    tau = d_band - ratio_model * d_latch
    if tau < _MIN_REG_LAG_MS:
        return
    info.regulator_lag_ms = float(tau)
    info.notes.append(
        f"structure: reg_pilot_lag (data τ_band/τ_latch {ratio_data:.2f} > "
        f"{LAG_RATIO_MARGIN:g} × the model's {ratio_model:.2f}: the regulated branch lags "
        f"through a path the latch does not see; start τ = {tau:.0f} ms)"
    )


@quiet_design_checks  # its probes are not the user's values
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
    latch = _measured_latches(qs)
    for tr in qs:
        if tr.name in latch:
            k, i = latch[tr.name], _period_mean(tr, _current(tr))
            info.latch_currents_mA[tr.name] = (float(i[k[0]]), float(i[k[1]]))
    params = _static_stage(model, start, qs, latch, settings, free, budget_s, info)
    params = _threshold_stage(model, params, qs[:3], latch, settings, free, info)
    if settings.regulator_lag == "auto" and "rlag_w" not in {p.name for p in model.parameters}:
        _lag_stage(model, params, traces, settings, info)
    info.values = {n: params[n] for n in free if params[n] != start[n]}
    info.wall_s = time.perf_counter() - t0
    return params, info


def _with_law(
    model: CircuitModel, start: ParameterSet, law: str, values: dict[str, float]
) -> tuple[CircuitModel, ParameterSet]:
    """``model`` with flexible law ``law``: every start value kept, ``values`` set (clipped
    to their bounds)."""
    new_model = model.with_effects(law)
    specs = new_model.default_params()
    names = {p.name for p in new_model.parameters}
    kept = {n: start[n] for n in start if n in names}
    for n, v in values.items():
        spec = specs.spec(n)
        kept[n] = float(min(max(v, spec.lower), spec.upper))
    return new_model, new_model.params(**kept)


def free_latch_structure(
    model: CircuitModel, start: ParameterSet, info: StagedStart
) -> tuple[CircuitModel, ParameterSet]:
    """The model with ``latch_free_thresholds`` and a start at the measured thresholds.

    Used when the staged start found the datasheet latch's area-ratio tie violated by
    the training data: the free-threshold law has the same number of parameters (two
    thresholds for preload and rate), without the tie. Every other start value is kept.
    """
    values = {}
    if info.thresholds_bar is not None:
        values = {"lthr_p_on": info.thresholds_bar[0], "lthr_p_off": info.thresholds_bar[1]}
    info.notes.append(
        "structure: latch_free_thresholds (same parameter count as the datasheet latch's "
        "preload and rate, without the area-ratio tie the training data violate)"
    )
    return _with_law(model, start, "latch_free_thresholds", values)


def regulator_lag_structure(
    model: CircuitModel, start: ParameterSet, info: StagedStart
) -> tuple[CircuitModel, ParameterSet]:
    """The model with ``reg_pilot_lag`` on (weight 1) at the staged start's time constant."""
    values = {"rlag_w": 1.0, "rlag_tau": info.regulator_lag_ms}
    return _with_law(model, start, "reg_pilot_lag", values)


#: The line-select latch is kept when it brings the fast ramps' worse latch-snap offset
#: below this fraction of the feedback-exhaust latch's (both matched on the slow ramps).
LATCH_PORT_GAIN = 0.7


@quiet_design_checks  # its probes are not the user's values
def latch_port_structure(
    model: CircuitModel,
    start: ParameterSet,
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
    info: StagedStart,
    budget_s: float = math.inf,
) -> tuple[CircuitModel, ParameterSet]:
    """Which latch port the fit uses, by the fast ramps' latch snaps; returns the matched start.

    Used when the lag signature found the regulated branch lagging through a path the latch
    does not see. In the datasheet circuit the latch exhausts the regulator's feedback, so
    the clutch's release runs through the regulator's recovery; a latch decoupled from the
    regulated branch may switch the clutch port to line instead (``latch_line_select``).
    Both are matched on the slow ramps (:func:`match_latch_snaps`) and simulated on (at
    most two of) the fastest training experiments with a measured snap: the line-select
    port is kept when the worse of its latch-on / latch-off offsets there is below
    :data:`LATCH_PORT_GAIN` times the exhaust latch's. Training experiments only.

    Parameters
    ----------
    model, start : CircuitModel, ParameterSet
        Structure and start after the staged start's latch and lag choices.
    traces : list of Trace
        Training experiments.
    free : tuple of str
        The fit's free parameters.
    settings : FitSettings
        Bounds and substeps.
    info : StagedStart
        Record of the staged start; ``latch_port`` and the matching's fields are filled in.
    budget_s : float
        Wall time (s) each of the two matchings may use.

    Returns
    -------
    (CircuitModel, ParameterSet)
        The chosen structure and its matched start.
    """
    fast = fastest_traces(traces)
    latch = _measured_latches(fast)
    used = [tr for tr in fast if tr.name in latch][:2]
    exhaust = match_latch_snaps(model, start, traces, free, settings, info, budget_s)
    if not used or fast[0] is quasi_static_traces(traces)[0]:
        info.notes.append("latch port: no fast ramp with a latch snap; feedback exhaust kept")
        return model, exhaust
    sel_model, sel_start = _with_law(model, start, "latch_line_select", {"lsel_w": 1.0})
    trial = StagedStart(static_experiments=info.static_experiments)
    selected = match_latch_snaps(sel_model, sel_start, traces, free, settings, trial, budget_s)
    worst = []
    for m, p in ((model, exhaust), (sel_model, selected)):
        f = _snap_offsets(m, p, used, latch, settings.substeps)
        worst.append(math.inf if f is None else float(np.max(np.abs(f))))
    info.latch_port = {"exhaust_fast_mA": worst[0], "line_select_fast_mA": worst[1]}
    keep = worst[1] < LATCH_PORT_GAIN * worst[0]
    verdict = (
        "structure: latch_line_select (the latch switches the clutch port to line)"
        if keep
        else "latch port: feedback exhaust kept"
    )
    info.notes.append(
        f"{verdict}; fast-ramp latch-snap offset, worse of on / off: exhaust "
        f"{worst[0]:.1f} mA, line select {worst[1]:.1f} mA"
    )
    if not keep:
        return model, exhaust
    info.latch_match_mA = trial.latch_match_mA
    info.latch_jacobian = trial.latch_jacobian
    info.values.update(trial.values)
    return sel_model, selected
