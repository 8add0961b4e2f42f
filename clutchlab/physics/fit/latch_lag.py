"""The latch lag stage of the fit: ``latch_on_lag`` from the snaps of the slowest and the
fastest training ramps, the latch re-matched with it.

A latch that trips on a lagging pressure (the clutch's, after a dwell) snaps later behind a
fast rising ramp than the model's pilot lets it, while it releases on its own: with one set
of thresholds the solver then trades the slow ramps' snaps against the fast ones'. On the
zoo's preisach_accumulator seed 1 the fitted model snapped on 4-6 mA late on the slow ramps
and 8-32 mA early on the fast ones (its latch lag 145 ms, the data's 192), and the cost is
flat between samples and steep at them, so the solver's thresholds stay there (session 62).
A symmetric latch pilot lag (``latch_pilot_lag``) moved the latch-on where the data ask and
delayed the release too: held-back error +0.8 and +6.3 % where it was added.

On the quasi-static training experiments (at most :data:`LAG_MAX_SLOW`) and the fastest ones
with a measured snap, the model's latch-on and latch-off current minus the measured one
(mA) is linear in the two thresholds (the fitted model's finite-difference Jacobian on the
slow experiments, mA per bar) and in the rate term ``r`` of
:class:`~clutchlab.physics.effects.flexible.LatchOnLag` (the latch-on threshold raised by
``r İ / 1000`` bar on a ramp rising at ``İ`` mA/s; the latch-off not moved). The slow rows
are weighted so that the slow and the fast experiments count as in the training RMS (each
experiment alike). The law is added where its leave-one-experiment-out offsets are below
:data:`LAG_GAIN` times the thresholds' alone and ``r`` is positive; one least-squares solve,
chord rounds (a simulation each), the best kept, and returned only when its simulated
offsets are below ``LAG_GAIN`` times those without it, and those exceed
:data:`~clutchlab.physics.fit.latch_band.BAND_MIN_MA` (mA, RMS). The fitter keeps it only
when it lowers the training RMS. Training experiments only.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...data import Trace
from ..effects.flexible import LatchDitherBand, LatchOnLag, LatchPilotLag, LatchRateBand
from ..model import CircuitModel
from ..parameters import ParameterSet, quiet_design_checks
from .latch_band import (
    BAND_MIN_MA,
    _fitted_jacobian,
    _loo_rms,
    _rms,
    chord_rounds,
    with_law_compiling,
)
from .settings import FitSettings
from .staged import (
    StagedStart,
    _latch_law,
    _measured_latches,
    _thresholds_of,
    _with_thresholds,
    fastest_traces,
    quasi_static_traces,
    ramp_rate,
    snap_offsets_each,
)

__all__ = ["LAG_FINISH_S", "LAG_GAIN", "LAG_MAX_SLOW", "lag_design", "latch_lag_structure"]

LAW = LatchOnLag.name
#: Laws whose stages already match the latch to the snaps: the stage does not run after them.
_MATCHED_BY = (LatchDitherBand.name, LatchRateBand.name, LatchPilotLag.name, LAW)
#: The law is added when its leave-one-experiment-out offsets, and then its simulated ones,
#: are below this fraction of the thresholds' alone (of those now). A one-parameter law: the
#: latch band stage's :data:`~clutchlab.physics.fit.latch_band.BAND_GAIN` (0.7) was set for a
#: five-parameter one (session 62; chosen on the training side of one scorecard dataset).
LAG_GAIN = 0.9
#: Quasi-static experiments the stage simulates (each is the longest of the training set).
LAG_MAX_SLOW = 3
#: Time (s) the stage leaves after its last simulation, besides the fitter's finish reserve:
#: the law adds a state, whose sensitivity code (for the result's standard errors) compiles
#: cold in ~9 s on one core, and the fitter's training-RMS check (~2 s on two).
LAG_FINISH_S = 10.0
#: Fastest experiments with a snap needed besides the slow ones.
_MIN_FAST = 2
_THR, _LAG = (0, 1), (0, 1, 2)


def lag_design(
    traces: list[Trace], latch: dict[str, tuple[int, int]], jacobian: np.ndarray
) -> np.ndarray:
    """The snap offsets' design matrix: ``Δd = A (Δp_on, Δp_off, r)``.

    Parameters
    ----------
    traces : list of Trace
        Experiments with a measured snap, in the order of the offsets.
    latch : dict of str to (int, int)
        Their measured latch-on / latch-off sample indices by name (only the names are used).
    jacobian : ndarray, shape (2, 2)
        d(latch-on, latch-off offset, mA) / d(latch-on, latch-off threshold, bar).

    Returns
    -------
    ndarray, shape (2 n, 3)
        Rows latch-on and latch-off of each trace; columns mA per bar (the thresholds) and
        mA per (bar per A/s) (the law: the latch-on row's threshold column × ``İ / 1000``,
        ``İ`` the trace's ramp rate, mA/s; 0 on the latch-off row).
    """
    jac = np.asarray(jacobian, float)
    rows = []
    for tr in traces:
        if tr.name not in latch:
            raise KeyError(f"no measured snap of {tr.name!r}")
        rate = ramp_rate(tr)
        # the law raises the latch-on threshold by r R / 1000 (bar) while the command rises;
        # at the latch-off the command falls: nothing
        rows.append([*jac[0], jac[0, 0] * 1e-3 * rate])
        rows.append([*jac[1], 0.0])
    return np.asarray(rows)


def _system(model, params, traces, free, settings, info):
    """``(used, latch, d0, scale, a)`` at ``params`` — the experiments, their snaps'
    indices, the offsets (mA) and the design matrix, both divided by ``scale`` (the rows'
    weights: the slow ones count for every quasi-static experiment with a snap) — or a
    reason (str) why there is none."""
    named = [n for n in _MATCHED_BY if n in model.effect_names]
    if named:
        return f"the model names {', '.join(named)} (its stage matched the latch)"
    if _latch_law(model, free) is None or info is None or info.latch_jacobian is None:
        return "latch not matched"
    slow = quasi_static_traces(traces)
    slow_names = {tr.name for tr in slow}
    fast = [tr for tr in fastest_traces(traces) if tr.name not in slow_names]
    latch = _measured_latches(slow + fast)
    n_slow = sum(tr.name in latch for tr in slow)
    slow = [tr for tr in slow if tr.name in latch][:LAG_MAX_SLOW]
    fast = [tr for tr in fast if tr.name in latch]
    if not slow or len(fast) < _MIN_FAST:
        return f"{len(slow)} slow and {len(fast)} fast experiments with a snap"
    used = slow + fast
    d0 = snap_offsets_each(model, params, used, latch, settings.substeps)
    if d0 is None:
        return "the model does not snap on every experiment used"
    jac, _ = _fitted_jacobian(
        model, params, slow, latch, free, settings, d0[: len(slow)], info.latch_jacobian
    )
    weight = np.repeat([n_slow / len(slow)] * len(slow) + [1.0] * len(fast), 2)
    scale = 1.0 / np.sqrt(weight)
    return used, latch, d0.ravel() / scale, scale, lag_design(used, latch, jac) / scale[:, None]


@quiet_design_checks  # its probes are not the user's values
def latch_lag_structure(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
    info: StagedStart,
    budget_s: float = math.inf,
) -> tuple[CircuitModel, ParameterSet]:
    """Add ``latch_on_lag`` where the slow and fast snaps ask for it, the latch re-matched.

    Parameters
    ----------
    model, params : CircuitModel, ParameterSet
        Structure and values after the solver and the latch band and rate stages.
    traces : list of Trace
        Training experiments (the quasi-static and the fastest ones with a snap are used).
    free : tuple of str
        The fit's free parameters; nothing is done unless the two latch parameters are free.
    settings : FitSettings
        Bounds and integrator substeps.
    info : StagedStart
        Record of the staged start (``latch_jacobian``); ``latch_band`` (keys prefixed
        ``lag_``) and ``notes`` are filled in.
    budget_s : float
        Wall time (s) after which no further simulation starts.

    Returns
    -------
    (CircuitModel, ParameterSet)
        The model with the law and the values (its ``r`` and the re-matched thresholds), or
        ``(model, params)`` unchanged.
    """
    deadline = time.perf_counter() + budget_s - LAG_FINISH_S
    if budget_s <= LAG_FINISH_S:
        info.notes.append("latch lag: no time left in the fit's limit; not estimated")
        return model, params
    system = _system(model, params, traces, free, settings, info)
    if isinstance(system, str):
        info.notes.append(f"latch lag: {system}; not estimated")
        return model, params
    used, latch, d0, scale, a = system
    loo_thr, loo_lag = _loo_rms(a, d0, _THR), _loo_rms(a, d0, _LAG)
    r = float(np.linalg.lstsq(a[:, list(_LAG)], -d0, rcond=None)[0][2])
    without, without_mA = _rms(d0), _rms(d0 * scale)
    info.latch_band.update(
        {
            "lag_experiments": float(len(used)),
            "lag_offsets_rms_mA": without_mA,
            "lag_loo_thresholds_mA": loo_thr,
            "lag_loo_mA": loo_lag,
            "lag_r_linear_bar": r,
        }
    )
    comparison = (
        f"leave-one-experiment-out snap offsets {loo_lag:.1f} mA with {LAW} "
        f"(r {r:.2f} bar per A/s), {loo_thr:.1f} mA with the thresholds alone, {without:.1f} mA "
        f"now"
        f" (weighted), on {len(used)} slow and fast experiments"
    )
    if not (without_mA > BAND_MIN_MA and loo_lag < LAG_GAIN * loo_thr and r > 0.0):
        info.notes.append(f"latch lag: not added ({comparison})")
        return model, params
    law = _latch_law(model, free)
    x0 = _thresholds_of(law, params)
    new_model, base = with_law_compiling(model, params, LAW, {}, traces, free, settings)
    spec = base.spec("lolag_r")
    lo, hi = settings.bounds.get("lolag_r", (spec.lower, spec.upper))

    def at(theta):
        p, _ = _with_thresholds(law, base, *(x0 + theta[:2]), settings.bounds)
        return p.replace(lolag_r=float(np.clip(theta[2], lo, hi)))

    best, rounds = chord_rounds(
        new_model, base, at, a, d0, _LAG, used, latch, settings, deadline, scale=scale
    )
    info.latch_band.update({"lag_offsets_after_mA": best[0], "lag_simulations": 3.0 + rounds})
    if best[1] is base or not best[0] < LAG_GAIN * without:
        info.notes.append(
            f"latch lag: not added (simulated offsets {without:.1f} → {best[0]:.1f} mA RMS, "
            f"weighted, not below {LAG_GAIN} × now; {comparison})"
        )
        return model, params
    info.latch_band["lag_r_bar"] = best[1]["lolag_r"]
    info.notes.append(
        f"structure: {LAW} after the solver (the fast ramps' latch-on lags the current more "
        f"than the slow ones' allows; the thresholds re-matched with it; held at the snaps' "
        f"values); {comparison}; offsets {without:.1f} → {best[0]:.1f} mA RMS (weighted), "
        f"r {best[1]['lolag_r']:.3f} bar per A/s"
    )
    return new_model, best[1]
