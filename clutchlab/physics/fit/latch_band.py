"""The latch band stage of the fit: ``latch_dither_band`` from the measured snaps.

A latch that must see its pilot beyond a threshold for a dwell time, or whose pilot passage
filters the dither, snaps and releases at currents that move with the dither amplitude by an
amount that depends on the dither frequency; the model's latch switches on the dithered pilot,
near the dither's crest. Where the training data's latch band does that, the fit adds the
:class:`~clutchlab.physics.effects.flexible.LatchDitherBand` law, held at values read off the
data, after the solver: fitted from zero by the solver the law lost its way (session 55, E4),
fitted from values read at the staged start it absorbed what the solver would have put
elsewhere (session 56, B1), added to the fitted model it did what the data ask (B2).

On every quasi-static training experiment with a measured snap, the model gives its latch-on
and latch-off current minus the measured one (mA). The law moves the latch-on threshold by
``+w`` and the latch-off threshold by ``−w`` (bar), ``w`` linear in its five parameters at
the dither amplitude and frequency of each snap; with the staged start's latch-matching
Jacobian (mA per bar of threshold) the offsets are linear in the two thresholds and the five
parameters. One least-squares solve of that system (the thresholds with the law, so the band's
centre moves too), then a few chord rounds (a simulation of the quasi-static experiments
each, the Jacobian kept), the best kept.

The law is added only where the data ask for it: the offsets that leave-one-experiment-out
predicts with the law must be below :data:`BAND_GAIN` times those predicted with the two
thresholds alone, and the thresholds alone must leave more than :data:`BAND_MIN_MA` (RMS).
The same test on the staged start's model (:func:`band_asked`) decides whether the solver
leaves :data:`BAND_RESERVE_S` of its time for the stage. The fitter keeps the law only when
it lowers the training RMS. Training experiments only.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...data import Trace
from ..effects.flexible import LatchDitherBand, dither_band_terms
from ..model import CircuitModel
from ..parameters import ParameterSet, quiet_design_checks
from .settings import FitSettings
from .staged import (
    StagedStart,
    _latch_law,
    _measured_latches,
    _period_mean,
    _thresholds_of,
    _with_law,
    _with_thresholds,
    quasi_static_traces,
    snap_offsets_each,
)

__all__ = [
    "BAND_FINISH_S",
    "BAND_GAIN",
    "BAND_MIN_MA",
    "BAND_RESERVE_S",
    "band_asked",
    "band_design",
    "latch_band_structure",
]

#: The law is adopted when its leave-one-experiment-out snap offsets (RMS) are below this
#: fraction of the thresholds' alone.
BAND_GAIN = 0.7
#: ... and the thresholds alone leave more than this (mA, RMS over latch-on and latch-off).
BAND_MIN_MA = 5.0
#: Quasi-static experiments with a measured snap needed (the law has five parameters).
BAND_MIN_EXPERIMENTS = 5
#: Chord rounds (one simulation of the quasi-static experiments each) after the first solve.
_BAND_ROUNDS = 3
#: Relative ridge on the law's columns (the five terms are close to collinear at three
#: dither frequencies).
_BAND_RIDGE = 1e-3
#: Solver time (s) kept for the stage when the staged start's snaps ask for the law.
BAND_RESERVE_S = 15.0
#: Time (s) the stage leaves the fitter at the end of its limit (the result's uncertainty
#: pass and per-experiment errors).
BAND_FINISH_S = 5.0
LAW = LatchDitherBand.name


def band_design(
    traces: list[Trace], latch: dict[str, tuple[int, int]], jacobian: np.ndarray
) -> np.ndarray:
    """The linearized snap offsets' design matrix: ``Δd = A θ``.

    Rows: latch-on and latch-off of each trace (in that order, trace by trace); columns:
    the latch-on and latch-off thresholds (bar), then the law's five parameters (bar).

    Parameters
    ----------
    traces : list of Trace
        Experiments with a measured snap (``latch``).
    latch : dict of str to (int, int)
        Measured latch-on / latch-off sample indices by experiment name.
    jacobian : ndarray, shape (2, 2)
        d(latch-on, latch-off offset, mA) / d(latch-on, latch-off threshold, bar).

    Returns
    -------
    ndarray, shape (2 n, 7)
        mA per bar.
    """
    rows = []
    for tr in traces:
        amp = _period_mean(tr, tr.get("dither_amp_mA"))
        freq = float(np.nanmedian(tr.get("dither_freq_Hz")))
        for branch, k in enumerate(latch[tr.name]):
            terms = np.array(dither_band_terms(float(amp[k]), freq))
            # the law moves latch-on by +w and latch-off by -w
            law = jacobian[branch, 0] * terms - jacobian[branch, 1] * terms
            rows.append(np.concatenate([jacobian[branch], law]))
    return np.asarray(rows)


def _solve(a: np.ndarray, d: np.ndarray, cols: slice) -> np.ndarray:
    """Least-squares ``θ`` (on ``cols``; 0 elsewhere) with ``a θ ≈ −d``, ridge on the law."""
    sub = a[:, cols]
    n = sub.shape[1]
    scale = np.sqrt(np.sum(sub**2, axis=0)) + 1e-12
    reg = np.zeros(n)
    reg[2:] = _BAND_RIDGE
    lhs = np.vstack([sub / scale, np.diag(reg)])
    rhs = np.concatenate([-d, np.zeros(n)])
    theta = np.zeros(a.shape[1])
    theta[cols] = np.linalg.lstsq(lhs, rhs, rcond=None)[0] / scale
    return theta


def _loo_rms(a: np.ndarray, d: np.ndarray, cols: slice) -> float:
    """RMS (mA) of each experiment's offsets as predicted from the others' solve."""
    res = []
    for e in range(a.shape[0] // 2):
        keep = np.ones(a.shape[0], bool)
        keep[2 * e : 2 * e + 2] = False
        theta = _solve(a[keep], d[keep], cols)
        res.append(d[~keep] + a[~keep] @ theta)
    return float(np.sqrt(np.mean(np.square(res))))


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(d))))


def _system(model, params, traces, free, settings, info):
    """The stage's linear system at ``params``, or a reason (str) why there is none.

    Returns ``(band_model, start, used, latch, d0, a)``: the model with the law (at 0),
    its parameters, the quasi-static experiments with a measured snap and their indices,
    the offsets (mA, latch-on and -off per experiment) and the design matrix."""
    if LAW in model.effect_names:
        return "the model names latch_dither_band"
    if _latch_law(model, free) is None or info is None or info.latch_jacobian is None:
        return "latch not matched"
    qs = quasi_static_traces(traces)
    latch = _measured_latches(qs)
    used = [tr for tr in qs if tr.name in latch]
    if len(used) < BAND_MIN_EXPERIMENTS:
        return f"{len(used)} quasi-static experiments with a snap (< {BAND_MIN_EXPERIMENTS})"
    band_model, start = _with_law(model, params, LAW, {})
    d0 = snap_offsets_each(band_model, start, used, latch, settings.substeps)
    if d0 is None:
        return "the model does not snap on every quasi-static experiment"
    a = band_design(used, latch, np.asarray(info.latch_jacobian, float))
    return band_model, start, used, latch, d0.ravel(), a


def _asks(d0: np.ndarray, a: np.ndarray) -> tuple[bool, dict[str, float], str]:
    """The adoption test: ``(asked, record, comparison text)``."""
    thresholds_only = _loo_rms(a, d0, slice(0, 2))
    with_law = _loo_rms(a, d0, slice(0, 7))
    record = {
        "experiments": float(len(d0) // 2),
        "offsets_rms_mA": _rms(d0),
        "loo_thresholds_mA": thresholds_only,
        "loo_law_mA": with_law,
    }
    asked = thresholds_only > BAND_MIN_MA and with_law < BAND_GAIN * thresholds_only
    text = (
        f"leave-one-experiment-out latch-snap offsets {with_law:.1f} mA with the law, "
        f"{thresholds_only:.1f} mA with the thresholds alone, on {len(d0) // 2} quasi-static "
        "experiments"
    )
    return asked, record, text


@quiet_design_checks  # its probes are not the user's values
def band_asked(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
    info: StagedStart,
) -> bool:
    """Whether the staged start's model asks for the latch band (the adoption test at
    ``params``); one simulation of the quasi-static experiments. Recorded in
    ``info.latch_band`` (keys prefixed ``staged_``) and ``info.notes``."""
    system = _system(model, params, traces, free, settings, info)
    if isinstance(system, str):
        return False
    *_, d0, a = system
    asked, record, text = _asks(d0, a)
    info.latch_band.update({f"staged_{k}": v for k, v in record.items()})
    info.notes.append(
        f"latch band at the staged start: {'time kept for it' if asked else 'not asked'} ({text})"
    )
    return asked


@quiet_design_checks  # its probes are not the user's values
def latch_band_structure(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
    info: StagedStart,
    budget_s: float = math.inf,
) -> tuple[CircuitModel, ParameterSet]:
    """Add ``latch_dither_band`` where the quasi-static snaps ask for it, at their values.

    Parameters
    ----------
    model, params : CircuitModel, ParameterSet
        Structure and fitted values (after the solver).
    traces : list of Trace
        Training experiments (the quasi-static ones with a measured snap are used).
    free : tuple of str
        The fit's free parameters; nothing is done unless the two latch parameters are free.
    settings : FitSettings
        Bounds and integrator substeps.
    info : StagedStart
        Record of the staged start (``latch_jacobian`` from the matching); ``latch_band``,
        ``values`` and ``notes`` are filled in.
    budget_s : float
        Wall time (s) after which no further simulation starts.

    Returns
    -------
    (CircuitModel, ParameterSet)
        The model with the law and the values (the law's and the matched thresholds), or
        ``(model, params)`` unchanged.
    """
    t0 = time.perf_counter()
    if budget_s <= 0:
        info.notes.append("latch band: no time left in the fit's limit; not estimated")
        return model, params
    system = _system(model, params, traces, free, settings, info)
    if isinstance(system, str):
        info.notes.append(f"latch band: {system}; not estimated")
        return model, params
    band_model, start, used, latch, d0, a = system
    asked, record, comparison = _asks(d0, a)
    info.latch_band.update(record)
    if not asked:
        info.notes.append(f"latch band: not added ({comparison})")
        return model, params
    law = _latch_law(model, free)
    x0 = _thresholds_of(law, start)
    names = LatchDitherBand.FIT
    bounds = {n: settings.bounds.get(n, (start.spec(n).lower, start.spec(n).upper)) for n in names}

    def at(theta):
        p, _ = _with_thresholds(law, start, *(x0 + theta[:2]), settings.bounds)
        law_values = {
            n: float(np.clip(start[n] + v, *bounds[n]))
            for n, v in zip(names, theta[2:], strict=True)
        }
        return p.replace(**law_values)

    best = (_rms(d0), start, d0)
    theta = _solve(a, d0, slice(0, 7))
    rounds = 0
    while rounds <= _BAND_ROUNDS and time.perf_counter() - t0 < budget_s:
        rounds += 1
        p = at(theta)
        d = snap_offsets_each(band_model, p, used, latch, settings.substeps)
        if d is None or _rms(d.ravel()) >= best[0]:
            break
        best = (_rms(d.ravel()), p, d.ravel())
        theta = theta + _solve(a, best[2], slice(0, 7))
    info.latch_band.update({"offsets_after_mA": best[0], "simulations": float(rounds + 1)})
    if best[1] is start:
        info.notes.append(f"latch band: no step lowered the snap offsets ({comparison})")
        return model, params
    info.notes.append(
        "structure: latch_dither_band after the solver (the latch band moves with the "
        f"dither; held at the snaps' values); {comparison}; offsets "
        f"{record['offsets_rms_mA']:.1f} → {best[0]:.1f} mA RMS"
    )
    return band_model, best[1]
