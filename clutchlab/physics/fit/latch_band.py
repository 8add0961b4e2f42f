"""The latch band stage of the fit: ``latch_dither_band`` and ``latch_line_threshold`` from
the measured snaps.

A latch that must see its pilot beyond a threshold for a dwell time, or whose pilot passage
filters the dither, snaps and releases at currents that move with the dither amplitude by an
amount that depends on the dither frequency; the model's latch switches on the dithered pilot,
near the dither's crest. A latch valve balanced against line pressure switches at currents
that follow the line pressure's wander; the datasheet valve's thresholds are fixed. Where the
training data's snaps do either, the fit adds the
:class:`~clutchlab.physics.effects.flexible.LatchDitherBand` and / or the
:class:`~clutchlab.physics.effects.flexible.LatchLineThreshold` law, held at values read off
the data, after the solver: fitted from zero by the solver the band law lost its way (session
55, E4), fitted from values read at the staged start it absorbed what the solver would have
put elsewhere (session 56, B1), added to the fitted model it did what the data ask (B2).

On every quasi-static training experiment with a measured snap, the model gives its latch-on
and latch-off current minus the measured one (mA). The band law moves the latch-on threshold
by ``+w`` and the latch-off threshold by ``−w`` (bar), ``w`` linear in its five parameters at
the dither amplitude and frequency of each snap; the line law moves them by ``r_on`` and
``r_off`` times the line pressure's excess over its reference at the snap. With the staged
start's latch-matching Jacobian (mA per bar of threshold) the offsets are linear in the two
thresholds and the laws' parameters. One least-squares solve of that system (the thresholds
with the laws, so the band's centre moves too), then a few chord rounds (a simulation of the
quasi-static experiments each, the Jacobian kept), the best kept.

A law is added only where the data ask for it: each structure's offsets are predicted
leave-one-experiment-out, and a structure must bring them below :data:`BAND_GAIN` times
those of every structure it contains (the thresholds alone; with both laws, each law alone),
with the thresholds alone leaving more than :data:`BAND_MIN_MA` (RMS); the eligible structure
with the lowest offsets is adopted. The same test on the staged start's model
(:func:`band_asked`) decides whether the solver leaves :data:`BAND_RESERVE_S` of its time for
the stage. The fitter keeps the laws only when they lower the training RMS. Training
experiments only.

The line law is offered (``FitSettings.latch_band = "auto"``, the default) only when the
training data log a line pressure that varies at the snaps (:data:`LINE_MIN_BAR`). It is
tested with the fitted model's own threshold Jacobian (the staged start's is taken on a
cruder model: on stribeck_supply s0 it gave the latch-on 51 mA per bar of the latch-off
threshold, the fitted model 8), and the solver always leaves the stage its time (the staged
start's test can miss what the fitted model's snaps show). Where the line law is not chosen,
the band law alone is tested and estimated with the staged start's Jacobian, as without a
line pressure (with the fitted model's, a dwell latch's held-back error rose 2.2 %).
Measured in sessions 58-59 (BENCHMARKS): held-back error −31 to −64 % on a line-referenced
latch (four seeds); unchanged to +0.34 % elsewhere. ``latch_band = "band"`` never offers the
line law (the default before session 59).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...data import Trace
from ..effects.flexible import LatchDitherBand, LatchLineThreshold, dither_band_terms
from ..model import CircuitModel
from ..parameters import ParameterSet, quiet_design_checks
from .sensitivity import compile_sensitivities_for
from .settings import FitSettings
from .staged import (
    StagedStart,
    _latch_law,
    _line,
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
    "LINE_MIN_BAR",
    "band_asked",
    "band_design",
    "band_law_rows",
    "chord_rounds",
    "latch_band_structure",
    "line_design",
]

#: The law is adopted when its leave-one-experiment-out snap offsets (RMS) are below this
#: fraction of the thresholds' alone.
BAND_GAIN = 0.7
#: ... and the thresholds alone leave more than this (mA, RMS over latch-on and latch-off).
#: After the solver the thresholds alone leave 0.3-0.5 mA on the stand, 0.6-1.4 on
#: preisach_accumulator, 1.4-9.1 on saturating_lugre, 4.1-8.6 on stribeck_supply's
#: line-referenced latch and 9-24 on quadratic_play's dwell latch (held-back datasets,
#: sessions 59-60). At 5 mA (sessions 56-59) the gate lay inside stribeck_supply's spread:
#: two fits of the same data that differed by one wall-clock-limited solver iteration read
#: 4.9 and 5.1 mA and took opposite decisions (session 60, G1). At 3 mA the nearest rows
#: are saturating_lugre's 2.6-2.7 mA, where a law would take off at most 1.4 mA.
BAND_MIN_MA = 3.0
#: Quasi-static experiments with a measured snap needed (the law has five parameters).
BAND_MIN_EXPERIMENTS = 5
#: Chord rounds (one simulation of the quasi-static experiments each) after the first solve.
_BAND_ROUNDS = 3
#: Relative ridge on the law's columns (the five terms are close to collinear at three
#: dither frequencies).
_BAND_RIDGE = 1e-3
#: Threshold step (bar) of the fitted model's finite-difference Jacobian.
_FD_BAR = 0.1
#: Solver time (s) kept for the stage when the staged start's snaps ask for a law (always
#: with the line law offered).
BAND_RESERVE_S = 15.0
#: Time (s) the stage leaves the fitter at the end of its limit (the result's uncertainty
#: pass and per-experiment errors).
BAND_FINISH_S = 5.0
LAW = LatchDitherBand.name
LINE_LAW = LatchLineThreshold.name
#: The line terms are offered only when the line pressure at the quasi-static snaps varies by
#: more than this (bar, standard deviation): otherwise their columns are zero.
LINE_MIN_BAR = 0.02
#: Columns of the stage's system: the two thresholds, the band law's five, the line law's two.
_THR = (0, 1)
_LAWS = {LAW: LatchDitherBand, LINE_LAW: LatchLineThreshold}
_GROUPS = {LAW: (2, 3, 4, 5, 6), LINE_LAW: (7, 8)}


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

    def terms_of(tr):
        amp = _period_mean(tr, tr.get("dither_amp_mA"))
        freq = float(np.nanmedian(tr.get("dither_freq_Hz")))
        return lambda k: dither_band_terms(float(amp[k]), freq)

    thresholds = np.vstack([jacobian for _ in traces])
    return np.hstack([thresholds, band_law_rows(traces, latch, jacobian, terms_of)])


def band_law_rows(traces: list[Trace], latch, jacobian: np.ndarray, terms_of) -> np.ndarray:
    """Columns of a law that widens the latch band by ``w = Σ pᵢ tᵢ`` (latch-on +w,
    latch-off −w) in the linearized snap offsets, rows as :func:`band_design`'s.

    ``terms_of(trace)`` gives a function of the snap's sample index returning the terms
    ``tᵢ``; each row is ``(J[b, on] − J[b, off]) tᵢ`` for branch ``b`` (mA per bar).
    """
    rows = []
    for tr in traces:
        terms_at = terms_of(tr)
        for branch, k in enumerate(latch[tr.name]):
            terms = np.array(terms_at(k))
            # the law moves latch-on by +w and latch-off by -w
            rows.append(jacobian[branch, 0] * terms - jacobian[branch, 1] * terms)
    return np.asarray(rows)


def line_design(
    traces: list[Trace], latch: dict[str, tuple[int, int]], jacobian: np.ndarray, p_ref: float
) -> np.ndarray:
    """The line law's columns of the linearized snap offsets: ``Δd = A (r_on, r_off)``.

    Rows as :func:`band_design`'s. The law raises the latch-on (latch-off) threshold by
    ``r_on`` (``r_off``) bar per bar of line pressure above ``p_ref`` at the snap.

    Parameters
    ----------
    traces, latch, jacobian
        As :func:`band_design`.
    p_ref : float
        Reference line pressure (bar).

    Returns
    -------
    ndarray, shape (2 n, 2)
        mA per unit of the slopes.
    """
    rows = []
    for tr in traces:
        line = _line(tr, len(tr))
        for branch, k in enumerate(latch[tr.name]):
            rows.append(jacobian[branch] * (float(line[k]) - p_ref))
    return np.asarray(rows)


def _line_reference(traces: list[Trace], latch: dict[str, tuple[int, int]]) -> float | None:
    """Median line pressure (bar) at the snaps of ``traces``; None when the training data log
    no line pressure or it varies by less than :data:`LINE_MIN_BAR` there."""
    if not all(tr.has("line_pressure_bar") for tr in traces):
        return None
    at = [float(_line(tr, len(tr))[k]) for tr in traces for k in latch[tr.name]]
    return float(np.median(at)) if np.std(at) > LINE_MIN_BAR else None


def _solve(a: np.ndarray, d: np.ndarray, cols, held: int = 2) -> np.ndarray:
    """Least-squares ``θ`` (on ``cols``; 0 elsewhere) with ``a θ ≈ −d``, ridge on the laws'
    columns (all of ``cols`` but the first ``held``: the thresholds)."""
    cols = list(cols)
    sub = a[:, cols]
    n = sub.shape[1]
    scale = np.sqrt(np.sum(sub**2, axis=0)) + 1e-12
    reg = np.zeros(n)
    reg[held:] = _BAND_RIDGE
    lhs = np.vstack([sub / scale, np.diag(reg)])
    rhs = np.concatenate([-d, np.zeros(n)])
    theta = np.zeros(a.shape[1])
    theta[cols] = np.linalg.lstsq(lhs, rhs, rcond=None)[0] / scale
    return theta


def _loo_rms(a: np.ndarray, d: np.ndarray, cols, held: int = 2) -> float:
    """RMS (mA) of each experiment's offsets as predicted from the others' solve."""
    res = []
    for e in range(a.shape[0] // 2):
        keep = np.ones(a.shape[0], bool)
        keep[2 * e : 2 * e + 2] = False
        theta = _solve(a[keep], d[keep], cols, held)
        res.append(d[~keep] + a[~keep] @ theta)
    return float(np.sqrt(np.mean(np.square(res))))


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(d))))


def _fitted_jacobian(
    model, params, used, latch, free, settings, d0, staged
) -> tuple[np.ndarray, int]:
    """d(latch-on, latch-off offset, mA) / d(threshold, bar) of the model at ``params``:
    finite differences over ``used`` (median over the experiments), and the simulations of
    them it took (two, fewer when one fails). The staged start's Jacobian was taken on its
    own, cruder model (session 58: on stribeck_supply s0 it gave the latch-on 51 mA per bar
    of the latch-off threshold, the fitted model 8); ``staged`` is kept when a perturbed
    model does not snap."""
    law = _latch_law(model, free)
    x0 = _thresholds_of(law, params)
    jac = np.zeros((2, 2))
    for j in range(2):
        p, clipped = _with_thresholds(law, params, *(x0 + _FD_BAR * np.eye(2)[j]), settings.bounds)
        d = None if clipped else snap_offsets_each(model, p, used, latch, settings.substeps)
        if d is None:
            return staged, j + (not clipped)
        jac[:, j] = np.median(d - d0, axis=0) / _FD_BAR
    return jac, 2


def _system(model, params, traces, free, settings, info, fitted=False):
    """The stage's linear system at ``params``, or a reason (str) why there is none.

    With ``settings.latch_band == "auto"`` and a line pressure that varies at the snaps, the
    line law's columns are offered and, on the ``fitted`` model, the thresholds' Jacobian is
    the model's own (finite differences), not the staged start's.

    Returns ``(used, latch, d0, a, p_ref)``: the quasi-static experiments with a measured
    snap and their indices, the offsets (mA, latch-on and -off per experiment), the design
    matrix (the thresholds, the band law's five columns and,
    when the line pressure varies at the snaps, the line law's two) and the line law's
    reference pressure (bar; None without its columns)."""
    if LAW in model.effect_names or LINE_LAW in model.effect_names:
        return f"the model names {LAW} or {LINE_LAW}"
    if _latch_law(model, free) is None or info is None or info.latch_jacobian is None:
        return "latch not matched"
    qs = quasi_static_traces(traces)
    latch = _measured_latches(qs)
    used = [tr for tr in qs if tr.name in latch]
    if len(used) < BAND_MIN_EXPERIMENTS:
        return f"{len(used)} quasi-static experiments with a snap (< {BAND_MIN_EXPERIMENTS})"
    d0 = snap_offsets_each(model, params, used, latch, settings.substeps)
    if d0 is None:
        return "the model does not snap on every quasi-static experiment"
    jac = np.asarray(info.latch_jacobian, float)
    p_ref = _line_reference(used, latch) if settings.latch_band == "auto" else None
    if p_ref is None:
        return used, latch, d0.ravel(), band_design(used, latch, jac), None
    if fitted:
        jac, runs = _fitted_jacobian(model, params, used, latch, free, settings, d0, jac)
        info.latch_band["jacobian_simulations"] = float(runs)
    a = np.hstack([band_design(used, latch, jac), line_design(used, latch, jac, p_ref)])
    return used, latch, d0.ravel(), a, p_ref


#: The structures the stage chooses from: the laws each adds to the thresholds.
_STRUCTURES = ((LAW,), (LINE_LAW,), (LAW, LINE_LAW))


def _columns(laws: tuple[str, ...]) -> tuple[int, ...]:
    return _THR + tuple(c for law in laws for c in _GROUPS[law])


def _asks(d0: np.ndarray, a: np.ndarray) -> tuple[tuple[str, ...], dict[str, float], str]:
    """The adoption test: ``(laws, record, comparison text)``; ``laws`` empty when none.

    Each structure's snap offsets are predicted leave-one-experiment-out. A structure is
    eligible when its offsets are below :data:`BAND_GAIN` times those of every structure it
    contains (the thresholds alone; with both laws, also each law alone); the eligible one
    with the lowest offsets is adopted, provided the thresholds alone leave more than
    :data:`BAND_MIN_MA`."""
    loo = {(): _loo_rms(a, d0, _THR)}
    for laws in _STRUCTURES:
        if all(_GROUPS[law][-1] < a.shape[1] for law in laws):
            loo[laws] = _loo_rms(a, d0, _columns(laws))
    eligible = [
        laws
        for laws in loo
        if laws and all(loo[laws] < BAND_GAIN * v for sub, v in loo.items() if set(sub) < set(laws))
    ]
    chosen = min(eligible, key=loo.__getitem__) if eligible else ()
    if loo[()] <= BAND_MIN_MA:
        chosen = ()
    record = {
        "experiments": float(len(d0) // 2),
        "offsets_rms_mA": _rms(d0),
        "loo_thresholds_mA": loo[()],
        "loo_law_mA": loo[(LAW,)],
    }
    if (LINE_LAW,) in loo:
        record["loo_line_mA"] = loo[(LINE_LAW,)]
        record["loo_law_line_mA"] = loo[(LAW, LINE_LAW)]
    parts = [f"{v:.1f} mA with {' + '.join(k)}" for k, v in loo.items() if k]
    text = (
        f"leave-one-experiment-out latch-snap offsets {', '.join(parts)}, "
        f"{loo[()]:.1f} mA with the thresholds alone, on {len(d0) // 2} quasi-static experiments"
    )
    return chosen, record, text


def with_law_compiling(
    model: CircuitModel,
    params: ParameterSet,
    law: str,
    held: dict[str, float],
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
) -> tuple[CircuitModel, ParameterSet]:
    """``model`` with the latch stage's law ``law`` (``params`` kept, ``held`` set), its
    sensitivity code compiling on the other core meanwhile: the result's standard errors
    need it, and cold it would add ~6-9 s after the stage's simulations."""
    new_model, base = _with_law(model, params, law, held)
    compile_sensitivities_for(
        new_model, traces, settings.substeps, settings.drive, len(free), background=True
    )
    return new_model, base


def chord_rounds(model, base, at, a, d0, cols, used, latch, settings, deadline, held=2, scale=1.0):
    """The stage's solve and its chord rounds: ``θ`` from the linear system ``a θ ≈ −d``,
    then, while a simulation of ``used`` lowers the snap offsets' RMS and before
    ``deadline`` (``time.perf_counter()``, s), ``θ`` moved by the system's solve of the
    offsets left (the Jacobian kept); at most :data:`_BAND_ROUNDS` + 1 simulations.

    Returns ``((rms, params, offsets), simulations)``: the best (``params`` is ``base`` when
    no step lowered the offsets ``d0``) and the simulations made. ``at(θ)`` gives the
    parameters of ``θ`` (on ``cols``, the first ``held`` of them the thresholds). The
    offsets are the simulated ones (mA) divided by ``scale`` (a number, or one per row of
    ``a``), as ``d0`` and ``a`` are."""
    best = (_rms(d0), base, d0)
    theta = _solve(a, d0, cols, held)[list(cols)]
    rounds = 0
    while rounds <= _BAND_ROUNDS and time.perf_counter() < deadline:
        rounds += 1
        p = at(theta)
        d = snap_offsets_each(model, p, used, latch, settings.substeps)
        if d is None or _rms(d.ravel() / scale) >= best[0]:
            break
        best = (_rms(d.ravel() / scale), p, d.ravel() / scale)
        theta = theta + _solve(a, best[2], cols, held)[list(cols)]
    return best, rounds


@quiet_design_checks  # its probes are not the user's values
def band_asked(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    free: tuple[str, ...],
    settings: FitSettings,
    info: StagedStart,
) -> bool:
    """Whether the solver leaves the latch band stage its time: the staged start's model
    asks for a law (the adoption test at ``params``), or the line law is offered (its test is
    made on the fitted model: the staged start's cruder model can hide what the fitted one's
    snaps show, session 58). One simulation of the quasi-static experiments. Recorded in
    ``info.latch_band`` (keys prefixed ``staged_``) and ``info.notes``."""
    system = _system(model, params, traces, free, settings, info)
    if isinstance(system, str):
        return False
    *_, d0, a, p_ref = system
    laws, record, text = _asks(d0, a)
    asked = bool(laws) or p_ref is not None
    info.latch_band.update({f"staged_{k}": v for k, v in record.items()})
    kept = "time kept for it" if asked else "not asked"
    info.notes.append(f"latch band at the staged start: {kept} ({text})")
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
    system = _system(model, params, traces, free, settings, info, fitted=True)
    if isinstance(system, str):
        info.notes.append(f"latch band: {system}; not estimated")
        return model, params
    used, latch, d0, a, p_ref = system
    laws, record, comparison = _asks(d0, a)
    if p_ref is not None and LINE_LAW not in laws:
        # the line law offered, not chosen: the band law alone, tested and estimated with
        # the staged start's Jacobian as without a line pressure (with the fitted model's,
        # a dwell latch's held-back error rose 2.2 %; session 58, L1)
        a = band_design(used, latch, np.asarray(info.latch_jacobian, float))
        laws, band_record, band_text = _asks(d0, a)
        record = {**record, **{f"band_{k}": v for k, v in band_record.items()}}
        comparison = (
            f"{comparison}; the band law alone, with the staged start's Jacobian: {band_text}"
        )
        p_ref = None
    info.latch_band.update(record)
    if not laws:
        info.notes.append(f"latch band: not added ({comparison})")
        return model, params
    law = _latch_law(model, free)
    x0 = _thresholds_of(law, params)
    cols = _columns(laws)
    held = {"llt_p_ref": p_ref} if LINE_LAW in laws else {}
    new_model, base = with_law_compiling(
        model, params, ", ".join(laws), held, traces, free, settings
    )
    names = [n for lw in laws for n in _LAWS[lw].FIT]
    bounds = {n: settings.bounds.get(n, (base.spec(n).lower, base.spec(n).upper)) for n in names}

    def at(theta):
        p, _ = _with_thresholds(law, base, *(x0 + theta[:2]), settings.bounds)
        law_values = {
            n: float(np.clip(v, *bounds[n])) for n, v in zip(names, theta[2:], strict=True)
        }
        return p.replace(**law_values)

    best, rounds = chord_rounds(
        new_model, base, at, a, d0, cols, used, latch, settings, t0 + budget_s
    )
    # the offsets at the start, the Jacobian's (line law offered) and the rounds'
    simulations = 1 + info.latch_band.get("jacobian_simulations", 0.0) + rounds
    info.latch_band.update({"offsets_after_mA": best[0], "simulations": simulations})
    if best[1] is base:
        info.notes.append(f"latch band: no step lowered the snap offsets ({comparison})")
        return model, params
    added = ", ".join(laws)
    info.notes.append(
        f"structure: {added} after the solver (the latch switch currents move with the "
        f"dither{' and the line pressure' if LINE_LAW in laws else ''}; held at the snaps' "
        f"values); {comparison}; offsets {record['offsets_rms_mA']:.1f} → {best[0]:.1f} mA RMS"
    )
    return new_model, best[1]
