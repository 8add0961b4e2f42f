"""The latch rate stage of the fit: ``latch_rate_band`` from the faster ramps' snaps.

The latch band stage (:mod:`~clutchlab.physics.fit.latch_band`) matches the model's latch
switch currents to the quasi-static (slowest) training ramps' snaps, with a dither shift
that is the same at every ramp rate. A latch that needs its pilot beyond a threshold for a
dwell time is moved less by the dither on a fast ramp than on a slow one: on the zoo's
quadratic_play the slow snaps were matched within ~1.5 mA while the fast ramps' snaps came
late by ~0.1-0.15 mA per mA of dither amplitude at 440 mA/s, half that at 220 mA/s, and
~0 with a 40 mA dither (session 60-61 diagnosis). This stage runs after the band stage, on
the training experiments that are not quasi-static: their latch-on and latch-off currents
minus the measured ones (mA) are linear, through the staged start's latch-matching
Jacobian (mA per bar of threshold), in the three parameters of
:class:`~clutchlab.physics.effects.flexible.LatchRateBand` (the thresholds and every other
value held: the slow snaps set them). One least-squares solve, then chord rounds (a
simulation of those experiments each), the best kept.

The law is added only where the data ask for it: its offsets predicted
leave-one-experiment-out must be below :data:`~clutchlab.physics.fit.latch_band.BAND_GAIN`
times the offsets without it, and those must exceed
:data:`~clutchlab.physics.fit.latch_band.BAND_MIN_MA` (RMS) — the band stage's test; the
simulated offsets at the values kept must be below ``BAND_GAIN`` times those without it too
(on held-back saturating_lugre s2 the linear test promised 3.8 → 2.2 mA, the simulations
gave 3.4, and the law kept raised the held-back error 3 %); and its dither term ``q₀`` must
not be positive (a dither shift that grows with the ramp rate is not a dwell latch: on
held-back preisach_accumulator s5, ``q₀`` = +0.15 bar, the law raised the held-back error
15 %; where it helped, ``q₀`` was −0.08 to −0.40 bar; session 61). The fitter keeps it
only when it lowers the training RMS. It runs only where the fit keeps time
for the band stage (:func:`~clutchlab.physics.fit.latch_band.band_asked`), and only on a
model with ``latch_dither_band`` (the law changes that band with the ramp rate; offered
without it, its rate term fitted the fast ramps' snaps as a delay that raised held-back
errors by ~3 % on two circuits whose latch has no dither band; session 61). Training
experiments only.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...data import Trace
from ..effects.flexible import LatchDitherBand, LatchRateBand, rate_band_terms
from ..inputs import _signal_or_meta
from ..model import CircuitModel
from ..parameters import ParameterSet, quiet_design_checks
from .latch_band import (
    BAND_GAIN,
    BAND_MIN_EXPERIMENTS,
    BAND_MIN_MA,
    _loo_rms,
    _rms,
    band_law_rows,
    chord_rounds,
    with_law_compiling,
)
from .settings import FitSettings
from .staged import (
    StagedStart,
    _latch_law,
    _measured_latches,
    _period_mean,
    quasi_static_traces,
    snap_offsets_each,
)

__all__ = ["latch_rate_structure", "rate_design"]

LAW = LatchRateBand.name
BAND_LAW = LatchDitherBand.name
_COLS = (0, 1, 2)


def rate_design(
    traces: list[Trace], latch: dict[str, tuple[int, int]], jacobian: np.ndarray
) -> np.ndarray:
    """The linearized snap offsets' design matrix for ``latch_rate_band``: ``Δd = A q``.

    Rows: latch-on and latch-off of each trace (in that order, trace by trace); columns:
    the law's three parameters (bar), each term taken at the dither amplitude, dither
    frequency and ramp rate (of the dither-period mean command, mA/s) of the snap.

    Parameters
    ----------
    traces, latch, jacobian
        As :func:`~clutchlab.physics.fit.latch_band.band_design`'s: the experiments with a
        measured snap, its sample indices by name, and d(offset, mA) / d(threshold, bar).

    Returns
    -------
    ndarray, shape (2 n, 3)
        mA per bar.
    """

    def terms_of(tr):
        amp = _period_mean(tr, _signal(tr, "dither_amp_mA"))
        freq = float(np.nanmedian(_signal(tr, "dither_freq_Hz")))
        rate = np.gradient(_period_mean(tr, tr.get("current_cmd_mA")), tr.time_s)
        return lambda k: rate_band_terms(float(amp[k]), freq, float(rate[k]))

    return band_law_rows(traces, latch, jacobian, terms_of)


def _signal(trace: Trace, name: str) -> np.ndarray:
    """Signal ``name``, else the trace's metadata value of it, else 0 — as the model's
    inputs take it (:mod:`~clutchlab.physics.inputs`; a bad metadata value is reported
    there, when the experiment is simulated)."""
    return _signal_or_meta(trace, name, 0.0, [])


def _system(model, params, traces, free, settings, info):
    """``(used, latch, d0, a)`` at ``params`` — the faster experiments with a measured snap,
    their indices, their offsets (mA) and the design matrix — or a reason (str)."""
    if LAW in model.effect_names:
        return f"the model names {LAW}"
    if BAND_LAW not in model.effect_names:
        # the law refines a dither band: without one its rate term alone fitted the fast
        # ramps' snaps as a delay that did not carry over to other ramp rates (held-back
        # stribeck_supply s4 +2.7 %, saturating_lugre s2 +3.1 %; session 61, R1)
        return f"no {BAND_LAW} in the model (the law changes a dither band with the ramp rate)"
    if _latch_law(model, free) is None or info is None or info.latch_jacobian is None:
        return "latch not matched"
    slow = {tr.name for tr in quasi_static_traces(traces)}
    fast = [tr for tr in traces if tr.name not in slow]
    if not all(tr.has("current_cmd_mA") for tr in fast):
        # the law's rate is the commanded current's (its filter state); without a command
        # the model's law does nothing, so the snaps cannot estimate it
        return "the faster experiments log no commanded current (current_cmd_mA)"
    latch = _measured_latches(fast)
    used = [tr for tr in fast if tr.name in latch]
    if len(used) < BAND_MIN_EXPERIMENTS:
        return f"{len(used)} faster experiments with a snap (< {BAND_MIN_EXPERIMENTS})"
    d0 = snap_offsets_each(model, params, used, latch, settings.substeps)
    if d0 is None:
        return "the model does not snap on every faster experiment"
    a = rate_design(used, latch, np.asarray(info.latch_jacobian, float))
    return used, latch, d0.ravel(), a


@quiet_design_checks  # its probes are not the user's values
def latch_rate_structure(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
    info: StagedStart,
    budget_s: float = math.inf,
) -> tuple[CircuitModel, ParameterSet]:
    """Add ``latch_rate_band`` where the faster ramps' snaps ask for it, at their values.

    Parameters
    ----------
    model, params : CircuitModel, ParameterSet
        Structure and values after the solver and the latch band stage.
    traces : list of Trace
        Training experiments (those that are not quasi-static, with a measured snap, are
        used).
    free : tuple of str
        The fit's free parameters; nothing is done unless the two latch parameters are free.
    settings : FitSettings
        Integrator substeps.
    info : StagedStart
        Record of the staged start (``latch_jacobian``); ``latch_band`` (keys prefixed
        ``rate_``) and ``notes`` are filled in.
    budget_s : float
        Wall time (s) after which no further simulation starts.

    Returns
    -------
    (CircuitModel, ParameterSet)
        The model with the law and its values, or ``(model, params)`` unchanged.
    """
    t0 = time.perf_counter()
    if budget_s <= 0:
        info.notes.append("latch rate band: no time left in the fit's limit; not estimated")
        return model, params
    system = _system(model, params, traces, free, settings, info)
    if isinstance(system, str):
        info.notes.append(f"latch rate band: {system}; not estimated")
        return model, params
    used, latch, d0, a = system
    without, loo = _rms(d0), _loo_rms(a, d0, _COLS, held=0)
    info.latch_band.update(
        {"rate_experiments": float(len(used)), "rate_offsets_rms_mA": without, "rate_loo_mA": loo}
    )
    comparison = (
        f"leave-one-experiment-out latch-snap offsets {loo:.1f} mA with {LAW}, {without:.1f} "
        f"mA without, on {len(used)} faster experiments"
    )
    if not (without > BAND_MIN_MA and loo < BAND_GAIN * without):
        info.notes.append(f"latch rate band: not added ({comparison})")
        return model, params
    new_model, base = with_law_compiling(model, params, LAW, {}, traces, free, settings)
    bounds = {
        n: settings.bounds.get(n, (base.spec(n).lower, base.spec(n).upper))
        for n in LatchRateBand.FIT
    }

    def at(theta):
        values = zip(LatchRateBand.FIT, theta, strict=True)
        return base.replace(**{n: float(np.clip(v, *bounds[n])) for n, v in values})

    best, rounds = chord_rounds(
        new_model, base, at, a, d0, _COLS, used, latch, settings, t0 + budget_s, held=0
    )
    info.latch_band.update({"rate_offsets_after_mA": best[0], "rate_simulations": 1.0 + rounds})
    if best[1] is base:
        info.notes.append(f"latch rate band: no step lowered the snap offsets ({comparison})")
        return model, params
    if not best[0] < BAND_GAIN * without:
        # the linearization promised more than the simulations gave (saturating_lugre s2:
        # 3.8 → 3.4 mA; kept, its held-back error rose 3 %; session 61, R1)
        info.notes.append(
            f"latch rate band: not added (the simulated offsets {without:.1f} → {best[0]:.1f} "
            f"mA RMS fall short of {BAND_GAIN} × without; {comparison})"
        )
        return model, params
    if best[1]["lrb_q0"] > 0.0:
        # a dither shift that grows with the ramp rate is not the dwell latch the law
        # stands for (held-back preisach_accumulator s5: q0 +0.15 bar, +15 %; session 61)
        info.notes.append(
            f"latch rate band: not added (its dither term q0 = {best[1]['lrb_q0']:+.3f} bar "
            f"would widen the dither's shift with the ramp rate; {comparison})"
        )
        return model, params
    info.notes.append(
        f"structure: {LAW} after the latch band stage (the faster ramps' switch currents "
        f"move with the dither by another amount than the slow ramps'; held at their "
        f"values); {comparison}; offsets {without:.1f} → {best[0]:.1f} mA RMS"
    )
    return new_model, best[1]
