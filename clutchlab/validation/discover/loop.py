"""Closing the loop: fit → residual → diagnostics → attribution → add effect → refit → repeat.

DESIGN §6. Among the candidates the score test finds significant, the best few are
refitted; a refit qualifies when both its information criterion and its linearized
leave-one-experiment-out prediction error (DESIGN §5: selection by
leave-one-experiment-out inside the training set) are lower than the current model's;
the qualifying candidate with the lowest such error is added (with fewer than two training
experiments there is no such error, and the lowest criterion decides). The loop stops when
none is significant, none qualifies, or at the effect limit. The test ramp is only scored.

Information criterion: ``BIC = n_eff · ln(RSS) + p · ln(n_eff)`` on the kept training
residuals, ``n_eff`` the effective number of independent residuals of the augmented
fit (:func:`~.residuals.effective_size`), so ``ΔBIC = n_eff · ln(RSS₁/RSS₀) + k · ln(n_eff)``
for ``k`` added free parameters. ``RSS₀`` is the current model's; when its fit had not
converged, the fit is first continued with the same budget as each candidate's refit
(so an added parameter does not look useful merely because its refit iterates further).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import asdict, replace

import numpy as np
from tqdm.auto import tqdm

from ...data import Dataset, Trace, dither_period_mean, dither_period_samples, pressure_metrics
from ...errors import ClutchlabError, FitError, FitWarning
from ...physics import CircuitModel, simulate
from ...physics.effects import EFFECTS
from ...physics.fit import FitResult, PhysicsFitter, resolve_free
from ...physics.parameters import ParameterSet
from .diagnostics import diagnose
from .residuals import (
    ResidualSet,
    loeo_rss,
    point_sums_of_squares,
    residual_problem,
    residual_set,
)
from .result import DiscoveryResult, IterationRecord, ModelState
from .scoring import CandidateScore, score_candidates
from .settings import DiscoverySettings
from .sparse import sparse_regression
from .warm import warm_sensitivities

__all__ = ["discover", "period_mean_metrics"]

#: Residual samples kept per experiment for the test-ramp figures.
_FIGURE_POINTS = 2000


def period_mean_metrics(
    model: CircuitModel, params: ParameterSet, traces: list[Trace]
) -> tuple[dict[str, float], dict[str, tuple[np.ndarray, np.ndarray]]]:
    """RMSE (bar) and fit % of the dither-period-mean pressure over ``traces`` (concatenated).

    Returns the metrics and, per trace, ``(nominal current mA, residual bar)`` thinned
    for figures. NaN metrics for no traces.
    """
    if not traces:
        return {"rmse_bar": math.nan, "fit_pct": math.nan}, {}
    meas, pred, curves = [], [], {}
    for tr in traces:
        n = dither_period_samples(tr)
        y = dither_period_mean(tr.get("clutch_pressure_bar"), n)
        yh = dither_period_mean(simulate(model, params, tr).pressure_bar, n)
        meas.append(y)
        pred.append(yh)
        step = max(len(y) // _FIGURE_POINTS, 1)
        cur = tr.get("current_cmd_mA") if tr.has("current_cmd_mA") else tr.get("current_mA")
        curves[tr.name] = (
            dither_period_mean(cur, n)[::step],
            (yh - y)[::step],
        )
    m = pressure_metrics(np.concatenate(meas), np.concatenate(pred))
    return {"rmse_bar": m["rmse_bar"], "fit_pct": m["fit_pct"]}, curves


def _split(dataset: Dataset | list[Trace], settings: DiscoverySettings):
    traces = list(dataset)
    train_ramps = set(settings.fit.train_ramps)
    train = [t for t in traces if t.ramp in train_ramps]
    test = [t for t in traces if t.ramp in set(settings.test_ramps)]
    if not train:
        ramps = sorted({str(t.ramp) for t in traces})
        raise FitError(
            f"no training experiments: ramps {sorted(train_ramps)} not in the dataset "
            f"(it has {ramps})"
        )
    return train, test


def _run_fit(
    model: CircuitModel,
    train: list[Trace],
    settings: DiscoverySettings,
    free: tuple[str, ...],
    start: ParameterSet | None,
) -> FitResult:
    """Fit; a fit that stops short returns its best iterate (discovery's refits are short by
    design, so the FitWarning saying so is not shown; the status is in the result)."""
    warm_sensitivities(model, train, settings.fit, len(free))
    fitter = PhysicsFitter(model, replace(settings.fit, free=free), start)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            return fitter.fit(train).result_
    except FitError as exc:
        best = getattr(exc, "result", None)
        if best is None:
            raise
        return best


def _state(
    fit: FitResult,
    train: list[Trace],
    test: list[Trace],
    settings: DiscoverySettings,
    jacobian: bool,
) -> ModelState:
    model, params = fit.model(), fit.params()
    problem = residual_problem(model, params, tuple(fit.free), train, settings.fit)
    if jacobian:
        warm_sensitivities(model, train, settings.fit, len(fit.free))
        problem.start_workers(train, settings.fit.workers)
    try:
        res = residual_set(problem, train, jacobian=jacobian, snap_guard_s=settings.snap_guard_s)
    finally:
        problem.close()
    train_m, _ = period_mean_metrics(model, params, train)
    test_m, curves = period_mean_metrics(model, params, test)
    return ModelState(fit, res, train_m, test_m, curves)


def _with_jacobian(state: ModelState, train, test, settings) -> ModelState:
    if state.residual.jacobian is not None:
        return state
    model, params = state.fit.model(), state.fit.params()
    problem = residual_problem(model, params, tuple(state.fit.free), train, settings.fit)
    warm_sensitivities(model, train, settings.fit, len(state.fit.free))
    problem.start_workers(train, settings.fit.workers)
    try:
        state.residual = residual_set(
            problem, train, jacobian=True, snap_guard_s=settings.snap_guard_s
        )
    finally:
        problem.close()
    return state


#: Fractions of the one-step strength estimate tried as refit starts (besides the default):
#: the estimate is a linear extrapolation, far off when the strength enters nonlinearly
#: (a quadratic strength probed near zero overshoots by ``s_true / (2 s_probe)``).
START_FRACTIONS = (1.0, 0.5, 0.25, 0.1)


def _refit_start(
    cand: CircuitModel,
    values: dict[str, float],
    score: CandidateScore,
    train: list[Trace],
    settings: DiscoverySettings,
    keep: np.ndarray,
) -> ParameterSet:
    """Start of a confirmatory refit: the current fit plus the effect.

    Fitted non-strength parameters (a lag's time constant) start at the grid value where
    the score was largest. Fitted strengths start at the best — by the kept residual sum
    of squares, one simulation each — of :data:`START_FRACTIONS` × the one-step (score)
    estimate and the default strength.
    """
    cls = EFFECTS[score.effect]
    specs = {p.name: p for p in cand.parameters}
    base = dict(values) | dict(score.nuisance)
    fitted = [n for n in score.strength if n in cls.fit_parameters()]
    if not fitted:
        return cand.params(**base)
    trials = [{n: f * score.strength[n] for n in fitted} for f in START_FRACTIONS]
    trials.append({n: specs[n].default for n in fitted})
    clipped = [
        {n: min(max(v, specs[n].lower), specs[n].upper) for n, v in trial.items()}
        for trial in trials
    ]
    try:
        rss = point_sums_of_squares(cand, base, clipped, train, settings.fit, keep)
    except ClutchlabError:
        rss = [math.inf] * len(clipped)
    k = int(np.argmin(rss)) if np.any(np.isfinite(rss)) else len(clipped) - 1
    return cand.params(**base, **clipped[k])


def _reference(
    current: ModelState, train: list[Trace], settings: DiscoverySettings
) -> tuple[ResidualSet, dict]:
    """The residual (with Jacobian) the candidates' refits are compared with.

    A converged current fit is its own reference. A fit that stopped short of its
    optimum is first continued from its best iterate with the same budget as every
    candidate's refit — otherwise any added parameter would look useful merely because
    its refit iterates further. The better of the two is the reference.
    """
    res = current.residual
    if current.fit.success:
        return res, {"kind": "current fit (converged)", "rss_bar2": res.kept_rss}
    t0 = time.perf_counter()
    _say(settings, "continuing the current fit (not converged) as the reference")
    try:
        fit = _run_fit(current.model, train, settings, tuple(current.fit.free), current.params)
        model, params = fit.model(), fit.params()
        problem = residual_problem(model, params, tuple(fit.free), train, settings.fit)
        warm_sensitivities(model, train, settings.fit, len(fit.free))
        problem.start_workers(train, settings.fit.workers)
        try:
            again = residual_set(problem, train, True, settings.snap_guard_s)
        finally:
            problem.close()
    except (ClutchlabError, ArithmeticError, ValueError) as exc:
        kind = f"current fit (its continuation failed: {exc})"
        return res, {"kind": kind, "rss_bar2": res.kept_rss}
    info = {
        "rss_before_bar2": res.kept_rss,
        "status": fit.status,
        "wall_s": time.perf_counter() - t0,
    }
    if math.isfinite(again.kept_rss) and again.kept_rss < res.kept_rss:
        kind = "current fit continued from its best iterate"
        return again, info | {"kind": kind, "rss_bar2": again.kept_rss}
    kind = "current fit (its continuation did not improve it)"
    return res, info | {"kind": kind, "rss_bar2": res.kept_rss}


def _confirm(
    score: CandidateScore,
    current: ModelState,
    rss_ref: float,
    train: list[Trace],
    test: list[Trace],
    settings: DiscoverySettings,
) -> ModelState | None:
    """Refit with the candidate; fill ``score.refit``; the new state, or None on failure."""
    t0 = time.perf_counter()
    cls = EFFECTS[score.effect]
    try:
        cand = current.model.with_effects(score.effect)
        free = tuple(current.fit.free)
        free += tuple(n for n in cls.fit_parameters() if n not in free)
        keep = current.residual.keep
        start = _refit_start(cand, current.fit.values, score, train, settings, keep)
        fit = _run_fit(cand, train, settings, free, start)
        state = _state(fit, train, test, settings, jacobian=True)
    except (ClutchlabError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        score.refit = {"status": f"failed: {exc}", "wall_s": time.perf_counter() - t0}
        return None
    rss1 = state.residual.kept_rss
    n_eff, _ = state.residual.effective()
    k = len(fit.free) - len(current.fit.free)
    if not (math.isfinite(rss1) and rss1 > 0 and rss_ref > 0):
        score.refit = {"status": "failed: non-finite residual", "wall_s": time.perf_counter() - t0}
        return None
    delta_bic = n_eff * math.log(rss1 / rss_ref) + k * math.log(max(n_eff, 1.0))
    cv = loeo_rss(state.residual)
    score.refit = {
        "loeo_rss_bar2": cv,
        "status": fit.status,
        "converged": bool(fit.success),
        "rss_bar2": rss1,
        "rss_ref_bar2": rss_ref,
        "n_eff": n_eff,
        "k": k,
        "delta_bic": delta_bic,
        "train_rmse_bar": state.train["rmse_bar"],
        "wall_s": time.perf_counter() - t0,
    }
    return state


def _say(settings: DiscoverySettings, text: str) -> None:
    if settings.progress:
        tqdm.write(f"discover: {text}")


def _iteration(
    index: int,
    current: ModelState,
    pool: tuple[str, ...],
    train: list[Trace],
    test: list[Trace],
    settings: DiscoverySettings,
    n_added: int,
) -> IterationRecord:
    """One turn: diagnose the residual, score the candidates, confirm, decide."""
    t_it = time.perf_counter()
    current = _with_jacobian(current, train, test, settings)
    res = current.residual
    diag = diagnose(res, settings.max_lag_s)
    sparse = sparse_regression(res, settings.sparse_threshold)
    names = [c for c in pool if c not in current.model.effect_names]
    level = settings.alpha / max(len(names), 1)
    _say(settings, f"iteration {index}: residual {diag.summary()}")

    reference: dict = {}
    states: dict[str, ModelState] = {}
    expansions = ["zero"]

    def record(effect, decision, scores, after, delta=None) -> IterationRecord:
        return IterationRecord(
            reference=reference,
            refits=states,
            index=index,
            effect=effect,
            decision=decision,
            candidates=scores,
            before=current,
            after=after,
            diagnostics=diag,
            sparse=sparse,
            delta_bic=delta,
            threshold_p=level,
            wall_s=time.perf_counter() - t_it,
            expansions=tuple(expansions),
        )

    if not names:
        return record(None, "no candidates left", [], current)
    if n_added >= settings.max_effects:
        return record(None, "effect limit reached", [], current)

    refits: dict[str, dict] = {}
    ref: list = []

    def score(expansion: str = "zero", previous=None) -> list[CandidateScore]:
        # candidates refitted already keep their score: they would not be refitted again
        return score_candidates(
            names,
            current.model,
            current.params,
            train,
            res,
            settings.fit,
            alpha=settings.alpha,
            min_share=settings.min_share,
            probe_fraction=settings.probe_fraction,
            progress=settings.progress,
            expansion=expansion,
            previous=previous,
            keep=frozenset(refits),
        )

    _say(settings, f"scoring {len(names)} candidate effects")
    scores = score()

    def attempt(scores: list[CandidateScore]) -> tuple[CandidateScore | None, str]:
        """Refit the best significant candidates (each once); the one to add, or why none."""
        significant = [s for s in scores if s.significant]
        for s in significant:
            if s.effect in refits:
                s.refit = refits[s.effect]
        fresh = [s for s in significant if s.effect not in refits]
        if not fresh:
            return None, "no significant effect" if not significant else "no new candidate"
        best_stat = fresh[0].statistic
        confirm = [s for s in fresh if s.statistic >= settings.confirm_ratio * best_stat]
        confirm = confirm[: settings.confirm_top]
        if not ref:
            ref_res, ref_info = _reference(current, train, settings)
            reference.update(ref_info)
            reference["loeo_rss_bar2"] = loeo_rss(ref_res)
            ref.append(ref_res)
        rss_ref, cv_ref = ref[0].kept_rss, reference["loeo_rss_bar2"]
        for s in confirm:
            _say(settings, f"refitting with {s.effect} (score {s.statistic:.1f})")
            state = _confirm(s, current, rss_ref, train, test, settings)
            refits[s.effect] = s.refit
            if state is not None:
                states[s.effect] = state
        ok = [s for s in significant if s.effect in states and s.refit["delta_bic"] < 0]
        if not ok:
            return None, "information criterion did not improve"
        if cv_ref is None:
            return min(ok, key=lambda s: s.refit["delta_bic"]), "added"
        ok = [s for s in ok if (s.refit["loeo_rss_bar2"] or math.inf) < cv_ref]
        if not ok:
            return None, "no leave-one-experiment-out improvement"
        return min(ok, key=lambda s: s.refit["loeo_rss_bar2"]), "added"

    chosen, decision = attempt(scores)
    if chosen is None and not diag.whiteness.get("white", True):
        # about to leave a structured (non-white) residual unexplained: look again, with
        # each candidate's strength profiled over multiples of its default (see the
        # scoring module). Not gated on the signature: a smooth residual has few
        # effective samples, and its bias-corrected η² can stay below the signature
        # threshold even where it follows dI/dt with r = 0.5.
        _say(settings, f"{decision} at zero strength; profiling the strengths")
        expansions.append("profile")
        scores = score("profile", previous=scores)
        chosen, again = attempt(scores)
        decision = decision if again == "no new candidate" else again
    if chosen is None:
        return record(None, decision, scores, current)
    new = states[chosen.effect]
    _say(
        settings,
        f"added {chosen.effect}: train RMSE {current.train['rmse_bar']:.4f} → "
        f"{new.train['rmse_bar']:.4f} bar, test {current.test['rmse_bar']:.4f} → "
        f"{new.test['rmse_bar']:.4f} bar",
    )
    return record(chosen.effect, "added", scores, new, chosen.refit["delta_bic"])


def discover(
    dataset: Dataset | list[Trace],
    model: CircuitModel | None = None,
    settings: DiscoverySettings | None = None,
    start: ParameterSet | None = None,
) -> DiscoveryResult:
    """Find the library effects the model lacks, add them, report error before and after.

    Parameters
    ----------
    dataset : Dataset or list of Trace
        Experiments with ramp labels; those of ``settings.fit.train_ramps`` are fitted
        and give every piece of evidence, those of ``settings.test_ramps`` are only
        scored (RMSE of the dither-period-mean clutch pressure, bar).
    model : CircuitModel, optional
        Starting model structure (effects already declared); the base circuit by default.
    settings : DiscoverySettings, optional
        Thresholds, limits, fit settings.
    start : ParameterSet, optional
        Starting values of the baseline fit (datasheet defaults by default).

    Returns
    -------
    DiscoveryResult
        ``best_model`` / ``params`` is the augmented model.

    Raises
    ------
    FitError
        When the baseline model cannot be fitted at all (no training experiments,
        bad bounds, divergence at the start). A candidate effect whose fit fails is
        reported in its evidence row, never raised.
    """
    t_start = time.perf_counter()
    settings = settings or DiscoverySettings()
    model = model or CircuitModel()
    train, test = _split(dataset, settings)
    pool = settings.candidates if settings.candidates is not None else tuple(EFFECTS)
    unknown = [c for c in pool if c not in EFFECTS]
    if unknown:
        raise FitError(f"unknown candidate effect(s) {unknown}; known: {sorted(EFFECTS)}")
    _say(settings, f"fitting {model.effect_names or 'the base model'} on {len(train)} experiments")
    free0 = resolve_free(model, settings.fit)
    current = _state(_run_fit(model, train, settings, free0, start), train, test, settings, True)
    baseline = current
    iterations: list[IterationRecord] = []
    for index in range(settings.max_effects + 1):
        record = _iteration(index, current, pool, train, test, settings, len(iterations))
        iterations.append(record)
        if record.effect is None:
            break
        current = record.after
    final_diag = diagnose(current.residual, settings.max_lag_s)
    last = iterations[-1]
    # "Unexplained" needs structure that follows an examined signal: a residual that is
    # not white but follows none of them (line-pressure wander, noise) names nothing.
    structured = not final_diag.whiteness.get("white", True)
    follows = bool(final_diag.signature)
    unexplained = last.effect is None and bool(last.candidates) and structured and follows
    signature = final_diag.signature if unexplained else []
    summary = _summary(iterations, unexplained, final_diag)
    return DiscoveryResult(
        iterations=iterations,
        baseline=baseline,
        final=current,
        unexplained=unexplained,
        signature=signature,
        summary=summary,
        train=[t.name for t in train],
        test=[t.name for t in test],
        wall_s=time.perf_counter() - t_start,
        settings=_settings_dict(settings),
    )


def _settings_dict(settings: DiscoverySettings) -> dict:
    d = asdict(settings)
    return {
        k: (list(v) if isinstance(v, tuple) else v)
        for k, v in d.items()
        if not isinstance(v, dict) or k != "fit"
    } | {"fit": {k: (list(v) if isinstance(v, tuple) else v) for k, v in d["fit"].items()}}


def _summary(iterations: list[IterationRecord], unexplained: bool, diag) -> str:
    added = [it for it in iterations if it.effect]
    parts = []
    for it in added:
        parts.append(
            f"added {it.effect} (ΔBIC {it.delta_bic:.1f}): training RMSE "
            f"{it.before.train['rmse_bar']:.4f} → {it.after.train['rmse_bar']:.4f} bar, "
            f"test-ramp RMSE {it.before.test['rmse_bar']:.4f} → "
            f"{it.after.test['rmse_bar']:.4f} bar"
        )
    last = iterations[-1]
    if unexplained:
        follows = ", ".join(diag.signature) or "no single signal"
        parts.append(
            "unexplained residual: no library effect explains a significant share of it "
            f"({last.decision}); it follows {follows}; no effect claimed for it"
        )
    elif last.decision == "effect limit reached":
        parts.append("stopped at the effect limit; the remaining residual was not scored")
    elif last.effect is None and diag.whiteness.get("white", True):
        parts.append(f"stopped: {last.decision}; the remaining residual is white")
    elif last.effect is None:
        parts.append(
            f"stopped: {last.decision}; the remaining residual is not white but follows "
            "none of the examined signals"
        )
    if not added and not unexplained:
        parts.insert(0, "no missing effect found")
    return "; ".join(parts) + "."
