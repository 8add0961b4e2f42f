"""Flexible-structure alternatives: an effect is claimed only when it predicts better than one.

Issue 17, "false attribution is the cardinal sin". A library effect that lowers the
information criterion and the leave-one-experiment-out error may still be the wrong
name: on a circuit whose component laws differ from clutchlab's, any added parameter
that bends the model towards the data helps, whatever physics it stands for. So before
an effect is added, each flexible component law (:data:`~clutchlab.physics.effects.
FLEXIBLE_LAWS`: a monotone VFS force correction, a play-operator hysteresis, free latch
thresholds, a regulator pilot lag and — once the model holds that one — a latch pilot
lag) that adds **at most as many free parameters** as the
effect and is not in the model yet is refitted the same way, on the same experiments,
from the same current fit; the effect is claimed only when it fits better than each such
alternative **and** predicts the left-out training experiments better on the geometric
mean of their held-out errors (:func:`beats`). Otherwise the report names the alternative
that explained the residual as well, and no effect is claimed for it.

The laws are refitted most flexible first (:func:`alternatives_for`), and the first that
matches ends the comparison. A law whose refit broke down (:func:`broke_down`) is not
beaten either, but the comparison goes on: a later law that matches is named instead,
and the broken one only when every other law was beaten.

Sizes are counted against the current fit's free parameters: ``latch_free_thresholds``
replaces the datasheet latch's preload and rate by its two thresholds (net 0 when those
are free), ``reg_pilot_lag`` and ``latch_pilot_lag`` free one time constant each (their
weight held at 1), the play operator three heights, the monotone force correction four
steps.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from ...data import Trace
from ...errors import ClutchlabError
from ...physics import CircuitModel
from ...physics.components.latch import latch_thresholds
from ...physics.effects import FLEXIBLE_LAWS
from ...physics.fit import FitSettings
from ...physics.fit.nlp import BREAKDOWN_STATUSES
from ...physics.fit.staged import measured_thresholds, quasi_static_traces
from ...physics.parameters import ParameterSet
from .refit import judge, residual_at, run_fit
from .residuals import ResidualSet
from .result import ModelState
from .settings import DiscoverySettings

__all__ = [
    "PILOT_LAG_STARTS_MS",
    "Alternative",
    "alternative_note",
    "alternatives_for",
    "beats",
    "broke_down",
    "fit_alternative",
    "held_out_log_ratio",
]

#: Time constants (ms) tried as the start of a pilot-lag alternative (the best by the
#: kept residual sum of squares, one simulation each): its time constant is the only
#: parameter it frees, and the objective is far from quadratic in it.
PILOT_LAG_STARTS_MS: tuple[float, ...] = (5.0, 20.0, 80.0, 300.0)

#: What a failing alternative refit may raise (recorded in its evidence, never raised).
_FAILURES = (ClutchlabError, ArithmeticError, ValueError)


@dataclass(frozen=True)
class Alternative:
    """A flexible law as an alternative to a candidate effect.

    Attributes
    ----------
    law : str
        Name of the flexible law (a key of ``FLEXIBLE_LAWS``).
    model : CircuitModel
        The current model with the law switched on.
    free : tuple of str
        Its free parameters: the current ones, minus those the law retires, plus the
        law's fit parameters.
    k : int
        Free parameters added to the current fit's (may be 0 or negative).
    """

    law: str
    model: CircuitModel
    free: tuple[str, ...]
    k: int


def alternatives_for(current: CircuitModel, free: tuple[str, ...], k: int) -> list[Alternative]:
    """The flexible laws not in ``current`` that add at most ``k`` free parameters.

    Parameters
    ----------
    current : CircuitModel
        The current model structure.
    free : tuple of str
        The current fit's free parameters.
    k : int
        Free parameters the candidate effect adds.

    Returns
    -------
    list of Alternative
        Most flexible first (most added parameters; then by name). A candidate is
        claimed only when it beats every law, so the order decides nothing but how soon
        a matched candidate stops: the law with the most freedom is the likeliest to
        match it, and the laws after it are then not refitted. A law with
        ``ALTERNATIVE_AFTER`` is offered only when ``current`` holds those laws.
    """
    out = []
    held = set(current.effect_names)
    for name, cls in FLEXIBLE_LAWS.items():
        if name in held or not cls.fit_parameters() or cls.WARM_ONLY:
            # a switch with nothing to fit (latch_line_select) is at its start the current
            # model itself: no alternative
            continue
        if not held.issuperset(cls.ALTERNATIVE_AFTER):
            continue
        retired = getattr(cls, "REPLACES", ())
        kept = tuple(n for n in free if n not in retired)
        new_free = kept + tuple(n for n in cls.fit_parameters() if n not in kept)
        size = len(new_free) - len(free)
        if size <= k:
            out.append(Alternative(name, current.with_effects(name), new_free, size))
    return sorted(out, key=lambda a: (-a.k, a.law))


def _best_start(alt: Alternative, points: list[ParameterSet], traces, settings) -> ParameterSet:
    """The point with the lowest kept residual sum of squares on ``traces`` (one simulation
    each; the first when none is finite)."""
    best, best_rss = points[0], math.inf
    for params in points:
        try:
            rss = residual_at(alt.model, params, alt.free, traces, settings, jacobian=False)
        except _FAILURES:
            continue
        if math.isfinite(rss.kept_rss) and rss.kept_rss < best_rss:
            best, best_rss = params, rss.kept_rss
    return best


def _start(
    alt: Alternative,
    values: dict[str, float],
    traces: list[Trace],
    settings: DiscoverySettings,
) -> ParameterSet:
    """The alternative's start, as informed by the data as a candidate's (whose strengths
    start at its score's one-step estimate): the current fit, with

    * free latch thresholds at the better of the fitted latch's thresholds and the
      thresholds the current model's pilot pressure has at the data's latch snaps
      (:func:`~clutchlab.physics.fit.staged.measured_thresholds`, slowest experiments);
    * a pilot lag (weight 1) at the best of :data:`PILOT_LAG_STARTS_MS`;
    * the play operator and the force correction at zero (the current model).
    """
    specs = {p.name: p for p in alt.model.parameters}
    base = {n: v for n, v in values.items() if n in specs}
    if alt.law == "latch_free_thresholds":
        points = [latch_thresholds(values)]
        current = alt.model.without_effects(alt.law)
        try:
            params = current.params(**{n: v for n, v in values.items() if n in _names(current)})
            found = measured_thresholds(
                current, params, quasi_static_traces(traces), substeps=settings.fit.substeps
            )
        except _FAILURES:
            found = "the pilot pressure could not be simulated"
        if not isinstance(found, str):
            points.append(found)
        on, off = specs["lthr_p_on"], specs["lthr_p_off"]
        starts = [
            alt.model.params(
                **base,
                lthr_p_on=min(max(p_on, on.lower), on.upper),
                lthr_p_off=min(max(p_off, off.lower), off.upper),
            )
            for p_on, p_off in points
        ]
        return _best_start(alt, starts, traces, settings)
    tau = _pilot_lag_time_constant(alt.law, specs)
    if tau is not None:
        on = dict.fromkeys(FLEXIBLE_LAWS[alt.law].STRENGTH, 1.0)
        starts = [alt.model.params(**base, **on, **{tau: ms}) for ms in PILOT_LAG_STARTS_MS]
        return _best_start(alt, starts, traces, settings)
    return alt.model.params(**base)


def _pilot_lag_time_constant(law: str, specs: dict) -> str | None:
    """The time constant (ms) a pilot-lag law frees — a held switch whose one fit
    parameter is a time constant (``reg_pilot_lag``, ``latch_pilot_lag``) — else None."""
    cls = FLEXIBLE_LAWS[law]
    fitted = cls.fit_parameters()
    if cls.HELD_SWITCH and len(fitted) == 1 and specs[fitted[0]].unit == "ms":
        return fitted[0]
    return None


def _names(model: CircuitModel) -> set[str]:
    return {p.name for p in model.parameters}


def fit_alternative(
    alt: Alternative,
    current: ModelState,
    traces: list[Trace],
    settings: DiscoverySettings,
    reference: ResidualSet,
    fit: FitSettings | None = None,
) -> dict:
    """Refit the alternative on ``traces`` from the current fit; its verdict.

    Parameters
    ----------
    alt : Alternative
        The flexible law and its free parameters.
    current : ModelState
        The current fit (the start).
    traces : list of Trace
        The experiments of the comparison (the screening subset or every training one).
    settings : DiscoverySettings
        Residual operator, fit settings.
    reference : ResidualSet
        The residual the candidate was judged against on the same experiments.
    fit : FitSettings, optional
        The refit's settings (a screening refit's); ``settings.fit`` by default.

    Returns
    -------
    dict
        ``law``, ``k``, ``status``, ``wall_s`` and, when the refit worked, the verdict of
        :func:`~.refit.judge` (``loeo_rss_bar2``, ``rss_bar2``, ``delta_bic`` …).
    """
    t0 = time.perf_counter()
    head = {"law": alt.law, "k": alt.k}
    try:
        start = _start(alt, current.fit.values, traces, settings)
        what = f"the refit of the flexible alternative {alt.law}"
        res_fit = run_fit(alt.model, traces, settings, alt.free, start, fit=fit, what=what)
        res = residual_at(res_fit.model(), res_fit.params(), res_fit.free, traces, settings)
    except _FAILURES as exc:
        return head | {"status": f"failed: {exc}", "wall_s": time.perf_counter() - t0}
    verdict = judge(res, reference.kept_rss, alt.k)
    if verdict is None:
        return head | {"status": "failed: non-finite residual", "wall_s": time.perf_counter() - t0}
    return head | {
        **{k: v for k, v in verdict.items() if k != "k"},
        "status": res_fit.status,
        "iterations": res_fit.iterations,
        "wall_s": time.perf_counter() - t0,
    }


def held_out_log_ratio(candidate: dict, alternative: dict) -> float | None:
    """Mean over the left-out training experiments of ``ln(e_candidate / e_alternative)``.

    ``e`` is each verdict's linearized held-out error of an experiment (bar², under
    ``loeo_bar2_by_experiment``); a negative value means the candidate predicts better on
    the geometric mean. None when either verdict lacks the per-experiment errors or they
    cover different experiments.
    """
    mine = candidate.get("loeo_bar2_by_experiment")
    theirs = alternative.get("loeo_bar2_by_experiment")
    if not mine or not theirs or set(mine) != set(theirs):
        return None
    tiny = 1e-300
    return sum(math.log(max(mine[e], tiny) / max(theirs[e], tiny)) for e in mine) / len(mine)


def broke_down(alternative: dict) -> str | None:
    """Why an alternative's refit says nothing about the law, or None when it does.

    A refit says nothing when it raised or left a non-finite residual (status
    ``"failed: …"``), or when its solver broke down (:data:`BREAKDOWN_STATUSES`): the law
    was not explored as far as the candidate it is compared with, whose refit had the
    same budget. A refit that converged or stopped at a limit is compared as it stands
    (its best iterate, like a candidate's).
    """
    status = str(alternative.get("status", ""))
    if status.startswith("failed"):
        return status
    broke = [s for s in BREAKDOWN_STATUSES if s in status]
    if not broke:
        return None
    rss, ref = alternative.get("rss_bar2", math.nan), alternative.get("rss_ref_bar2", math.nan)
    steps = alternative.get("iterations", "?")
    return f"{broke[0]} after {steps} iterations, at {rss:.4g} bar² (reference {ref:.4g})"


def beats(candidate: dict, alternative: dict) -> bool:
    """Whether a candidate's refit verdict is not matched by an alternative's.

    The candidate beats the alternative only when it is better **both** in-sample and out
    of sample:

    * it fits the same experiments strictly better (kept residual sum of squares
      ``rss_bar2``): an alternative with no more parameters that fits at least as well
      is at least as good under any penalty (the ``delta_bic`` of two refits use their
      own effective sample sizes);
    * it predicts the left-out training experiments better on the geometric mean of
      their held-out errors (:func:`held_out_log_ratio` < 0); without per-experiment
      errors on a sum (``loeo_rss_bar2``), and with one training experiment the fit
      alone decides.

    Why the geometric mean: it weighs each experiment's margin on the same relative
    scale, so neither one poorly determined term (the held-out error of the only slow
    ramp of a subset) nor a count that a subset's mix of ramps tilts (a lag that helps
    the three fast experiments of a five-experiment subset a little while the true
    effect predicts the two slow ones much better) decides alone. Why both: a flexible
    law that fits better is as good an explanation of the training data whatever a
    linearized held-out error says, and one that predicts better is whatever it fits.
    An alternative whose refit broke down (:func:`broke_down`) is not beaten: the
    candidate was not shown to predict better than the law, so it is not claimed
    (issue 17: false attribution is the cardinal sin; before session 32 such an
    alternative counted as beaten, and gave the one claim over 20 null datasets).
    """
    if broke_down(alternative) is not None or "rss_bar2" not in alternative:
        return False
    if alternative["rss_bar2"] <= candidate["rss_bar2"]:
        return False
    ratio = held_out_log_ratio(candidate, alternative)
    if ratio is not None:
        return bool(ratio < 0.0)
    mine, theirs = candidate.get("loeo_rss_bar2"), alternative.get("loeo_rss_bar2")
    if mine is None or theirs is None:
        return True
    return bool(mine < theirs)


def alternative_note(refit: dict | None) -> str:
    """One cell for an evidence table: the flexible laws a candidate's refit was compared
    with (on the screening subset or every training experiment) and the outcome —
    ``"beat reg_pilot_lag, latch_free_thresholds"``, ``"matched by reg_pilot_lag"``,
    ``"not compared: reg_pilot_lag's refit broke down"`` or ``""`` when it was not
    compared."""
    refit = refit or {}
    holder = refit if refit.get("alternatives") is not None else refit.get("screen") or {}
    rows = holder.get("alternatives")
    if not rows:
        return "" if rows is None else "none to compare"
    if holder.get("beats_alternatives"):
        return f"beat {', '.join(r['law'] for r in rows)}"
    # the law that decided (JSONs written before session 33 have it last)
    law = holder.get("matched_by", rows[-1]["law"])
    row = next((r for r in rows if r["law"] == law), rows[-1])
    if broke_down(row) is not None:
        return f"not compared: {row['law']}'s refit broke down"
    return f"matched by {row['law']}"
