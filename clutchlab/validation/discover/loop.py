"""Closing the loop: fit → residual → diagnostics → attribution → add effect → refit → repeat.

DESIGN §6. Among the candidates the score test finds significant, the best few are
refitted; a refit qualifies when both its information criterion and its linearized
leave-one-experiment-out prediction error (DESIGN §5: selection by
leave-one-experiment-out inside the training set) are lower than the current model's
(with fewer than two training experiments there is no such error, and the criterion
decides). The qualifying candidates are tried best criterion first (:func:`~.refit.
by_criterion`: the held-out error is the go / no-go, not the ranking, because with few
training ramps each fold predicts one ramp rate from the others and the true effect's
fold can be the worst); the first that also fits and predicts better than every flexible
component law of at most its size, refitted the same way (:mod:`.alternatives`), is
added; when none does, no effect is claimed for the residual. The loop stops when none is
significant, none qualifies, or at the effect limit. The test ramp is only scored.

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
from dataclasses import asdict

import numpy as np
from tqdm.auto import tqdm

from ...data import Dataset, Trace, dither_period_mean, dither_period_samples, pressure_metrics
from ...errors import ClutchlabError, FitError, FitWarning, warn_at_caller
from ...forkmap import default_workers
from ...physics import CircuitModel, SimulationSettings
from ...physics.effects import EFFECTS
from ...physics.fit import FitResult, PrefitPoint, at_fit_rate, period_mean_pairs, resolve_free
from ...physics.parameters import ParameterSet, quiet_design_checks
from .alternatives import alternatives_for, beats, broke_down, fit_alternative
from .deadline import DiscoveryTimeLimit, check_budget, discovery_budget
from .diagnostics import diagnose
from .refit import by_criterion, candidate_free, judge, refit_start, residual_at, run_fit
from .residuals import ResidualSet, loeo_evidence
from .result import DiscoveryResult, IterationRecord, ModelState
from .scoring import CandidateScore, score_candidates
from .screen import Screening, confirm_settings, screen_refit, screen_settings, screening
from .settings import DiscoverySettings
from .sparse import sparse_regression
from .warm import warm_sensitivities

__all__ = ["discover", "period_mean_metrics"]

#: Residual samples kept per experiment for the test-ramp figures.
_FIGURE_POINTS = 2000


def period_mean_metrics(
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    sim: SimulationSettings | None = None,
    workers: int | None = None,
) -> tuple[dict[str, float], dict[str, tuple[np.ndarray, np.ndarray]]]:
    """RMSE (bar) and fit % of the dither-period-mean pressure over ``traces`` (concatenated).

    ``sim``: the simulation settings (the defaults, as every scored ramp, when None).
    ``workers``: forked processes simulating the traces (the same numbers with any
    number; :func:`~clutchlab.forkmap.default_workers` when None).
    Returns the metrics and, per trace, ``(nominal current mA, residual bar)`` thinned
    for figures. NaN metrics for no traces.
    """
    if not traces:
        return {"rmse_bar": math.nan, "fit_pct": math.nan}, {}

    workers = workers or default_workers()
    means = period_mean_pairs(model, [params] * len(traces), traces, workers, sim)
    curves = {}
    for tr, (y, yh) in zip(traces, means, strict=True):
        step = max(len(y) // _FIGURE_POINTS, 1)
        cur = tr.get("current_cmd_mA") if tr.has("current_cmd_mA") else tr.get("current_mA")
        n = dither_period_samples(tr)
        curves[tr.name] = (dither_period_mean(cur, n)[::step], (yh - y)[::step])
    m = pressure_metrics(
        np.concatenate([y for y, _ in means]), np.concatenate([yh for _, yh in means])
    )
    return {"rmse_bar": m["rmse_bar"], "fit_pct": m["fit_pct"]}, curves


def _split(dataset: Dataset | list[Trace], settings: DiscoverySettings):
    traces = list(dataset)
    train_ramps = set(settings.fit.train_ramps)
    # at the fit's rate, so that the base fit, the screening refits and the evidence all
    # see the same samples (a no-op for data logged at up to 1.5 × that rate)
    train = at_fit_rate([t for t in traces if t.ramp in train_ramps], settings.fit.fit_rate_Hz)
    test = [t for t in traces if t.ramp in set(settings.test_ramps)]
    if not train:
        ramps = sorted({str(t.ramp) for t in traces})
        raise FitError(
            f"no training experiments: ramps {sorted(train_ramps)} not in the dataset "
            f"(it has {ramps})"
        )
    return train, test


def _state(
    fit: FitResult,
    train: list[Trace],
    test: list[Trace],
    settings: DiscoverySettings,
    jacobian: bool,
) -> ModelState:
    model, params = fit.model(), fit.params()
    res = residual_at(model, params, tuple(fit.free), train, settings, jacobian)
    workers = settings.fit.workers
    train_m, _ = period_mean_metrics(model, params, train, workers=workers)
    test_m, curves = period_mean_metrics(model, params, test, workers=workers)
    return ModelState(fit, res, train_m, test_m, curves)


def _with_jacobian(state: ModelState, train, settings) -> ModelState:
    if state.residual.jacobian is None:
        fit = state.fit
        state.residual = residual_at(fit.model(), fit.params(), tuple(fit.free), train, settings)
    return state


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
        what = "the current fit's continuation (the reference)"
        fit = run_fit(
            current.model, train, settings, tuple(current.fit.free), current.params, what=what
        )
        again = residual_at(fit.model(), fit.params(), tuple(fit.free), train, settings)
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
    screened: FitResult | None = None,
) -> ModelState | None:
    """Refit with the candidate on every training experiment; fill ``score.refit``; the
    new state, or None on failure.

    Without ``screened`` the refit is a whole fit from the current fit plus the effect;
    with it (the candidate's refit on the screening subset), the fit's refinement stage
    from there, and the screening verdict is kept under ``score.refit["screen"]``.
    """
    t0 = time.perf_counter()
    screen = {"screen": score.refit} if screened is not None else {}
    try:
        cand = current.model.with_effects(score.effect)
        free = candidate_free(tuple(current.fit.free), score.effect)
        if screened is None:
            keep = current.residual.keep
            start = refit_start(cand, current.fit.values, score, train, settings, keep)
            fit = run_fit(cand, train, settings, free, start, what=f"the refit with {score.effect}")
        else:
            start = cand.params(**screened.values)
            what = f"the confirmation of {score.effect} on every training experiment"
            fit = run_fit(
                cand, train, settings, free, start, confirm_settings(settings.fit), what=what
            )
        state = _state(fit, train, test, settings, jacobian=True)
    except (ClutchlabError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        score.refit = {"status": f"failed: {exc}", "wall_s": time.perf_counter() - t0, **screen}
        return None
    verdict = judge(state.residual, rss_ref, len(fit.free) - len(current.fit.free))
    if verdict is None:
        score.refit = {
            "status": "failed: non-finite residual",
            "wall_s": time.perf_counter() - t0,
            **screen,
        }
        return None
    score.refit = verdict | {
        "status": fit.status,
        "converged": bool(fit.success),
        "train_rmse_bar": state.train["rmse_bar"],
        "wall_s": time.perf_counter() - t0,
        **screen,
    }
    return state


def _qualifies(refit: dict, cv_ref: float | None) -> bool:
    """Lower information criterion and (when there is one) lower held-out error."""
    if "delta_bic" not in refit or not refit["delta_bic"] < 0:
        return False
    return cv_ref is None or (refit["loeo_rss_bar2"] or math.inf) < cv_ref


def _matched_decision(matched: dict[str, dict], scope: str) -> str:
    """The decision when every qualifying candidate was matched by a flexible law, or
    met one whose refit broke down (``matched``: candidate -> the law's verdict)."""
    why = {e: broke_down(v) for e, v in matched.items()}
    parts = []
    pairs = [f"{e} by {v['law']}" for e, v in matched.items() if why[e] is None]
    if pairs:
        parts.append(
            "a flexible law of at most the same size predicted the left-out experiments "
            f"as well ({', '.join(pairs)}; {scope})"
        )
    broken = [f"{e} against {v['law']}: {why[e]}" for e, v in matched.items() if why[e]]
    if broken:
        parts.append(
            "not compared with a flexible law of at most the same size whose refit broke "
            f"down ({'; '.join(broken)}; {scope})"
        )
    return "; ".join(parts) + ": no effect claimed"


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
    prefit: PrefitPoint | None = None,
) -> IterationRecord:
    """One turn: diagnose the residual, score the candidates, confirm, decide.

    ``prefit``: the current fit's own pre-fit optimum (the baseline fit's, in the first
    turn of a discovery that made it), the screening reference when it ran on the same
    subset."""
    t_it = time.perf_counter()
    # the training residual's Jacobian (one sensitivity run on every training experiment)
    # is computed only where it is used: scoring without a screening stage, and the
    # reference of a confirmation on all data (the residual itself is the same either way)
    res = current.residual
    diag = diagnose(res, settings.max_lag_s)
    sparse = sparse_regression(res, settings.sparse_threshold)
    names = [c for c in pool if c not in current.model.effect_names]
    level = settings.alpha / max(len(names), 1)
    _say(settings, f"iteration {index}: residual {diag.summary()}")

    reference: dict = {}
    states: dict[str, ModelState] = {}
    expansions = ["zero"]

    def record(effect, decision, scores, after, delta=None, limited=False) -> IterationRecord:
        if screen is not None and screen.info:
            reference["screening"] = screen.info
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
            time_limited=limited,
        )

    def stopped(stop: DiscoveryTimeLimit, scores) -> IterationRecord:
        _say(settings, f"{stop}: no effect claimed in iteration {index}")
        return record(None, f"stopped: {stop}; no effect claimed", scores, current, limited=True)

    screen: Screening | None = None
    if not names:
        return record(None, "no candidates left", [], current)
    if n_added >= settings.max_effects:
        return record(None, "effect limit reached", [], current)
    try:
        check_budget(f"iteration {index}")
    except DiscoveryTimeLimit as stop:
        return stopped(stop, [])

    # Long training data: the evidence is gathered on the pre-fit subset and only the
    # candidate chosen there is refitted on every training experiment (see .screen).
    screen = screening(current, train, settings, prefit)
    if screen is None:
        evidence_traces, evidence = train, _with_jacobian(current, train, settings).residual
    else:
        evidence_traces, evidence = screen.traces, screen.residual
        _say(settings, f"screening on {screen.describe()}")

    refits: dict[str, dict] = {}
    ref: list = []
    # flexible-law alternatives refitted in this iteration: (scope, law) -> verdict
    alt_verdicts: dict[tuple[str, str], dict] = {}
    # candidate -> the verdict of the flexible law that predicted as well (or broke down)
    matched: dict[str, dict] = {}

    def score(expansion: str = "zero", previous=None) -> list[CandidateScore]:
        # candidates refitted already keep their score: they would not be refitted again
        return score_candidates(
            names,
            current.model,
            current.params,
            evidence_traces,
            evidence,
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

    def full_reference() -> tuple[float, float | None]:
        if not ref:
            _with_jacobian(current, train, settings)
            ref_res, ref_info = _reference(current, train, settings)
            reference.update(ref_info)
            reference.update(loeo_evidence(ref_res))
            ref.append(ref_res)
        return ref[0].kept_rss, reference["loeo_rss_bar2"]

    def compile_ahead(confirm: list[CandidateScore], traces: list[Trace]) -> None:
        """Start compiling the code of the refits after the first (the other candidates,
        the flexible laws they may meet) while the first one runs."""
        free = tuple(current.fit.free)
        k_max = 0
        for s in confirm:
            cand_free = candidate_free(free, s.effect)
            k_max = max(k_max, len(cand_free) - len(free))
            if s is not confirm[0]:
                cand = current.model.with_effects(s.effect)
                warm_sensitivities(cand, traces, settings.fit, len(cand_free), background=True)
        if settings.alternatives:
            for alt in alternatives_for(current.model, free, k_max):
                warm_sensitivities(alt.model, traces, settings.fit, len(alt.free), background=True)

    def confirm_all(confirm: list[CandidateScore]) -> None:
        """Refit each on every training experiment (no screening stage)."""
        rss_ref, _ = full_reference()
        compile_ahead(confirm, train)
        for s in confirm:
            _say(settings, f"refitting with {s.effect} (score {s.statistic:.1f})")
            state = _confirm(s, current, rss_ref, train, test, settings)
            refits[s.effect] = s.refit
            if state is not None:
                states[s.effect] = state

    def alternatives_beaten(s: CandidateScore, scope: str, traces, reference_res, fit) -> bool:
        """Whether the candidate's refit predicts better than every flexible law of at most
        its size refitted on ``traces`` (each law refitted once per scope); recorded
        under ``s.refit["alternatives"]`` and, when not, the law under ``"matched_by"``.

        The laws come most flexible first and the first that matches ends the comparison.
        A law whose refit broke down is not beaten, but it does not end the comparison: a
        later law that matches is the better answer to name; the broken one is named only
        when every other law was beaten."""
        if not settings.alternatives:
            return True
        rows, broken = [], None
        for alt in alternatives_for(current.model, tuple(current.fit.free), s.refit["k"]):
            key = (scope, alt.law)
            if key not in alt_verdicts:
                _say(settings, f"refitting the flexible alternative {alt.law} ({scope})")
                alt_verdicts[key] = fit_alternative(
                    alt, current, traces, settings, reference_res, fit
                )
            rows.append(alt_verdicts[key])
            if beats(s.refit, rows[-1]):
                continue
            if broke_down(rows[-1]) is None:
                matched[s.effect] = rows[-1]
                break
            broken = broken or rows[-1]
        if s.effect not in matched and broken is not None:
            matched[s.effect] = broken
        s.refit["alternatives"] = rows
        s.refit["beats_alternatives"] = s.effect not in matched
        if s.effect in matched:
            s.refit["matched_by"] = matched[s.effect]["law"]
        return s.effect not in matched

    def screen_then_confirm(confirm: list[CandidateScore]) -> None:
        """Refit each on the subset; confirm on every training experiment the ones that
        qualify there and beat the flexible alternatives there, best criterion first,
        until one qualifies on all of them."""
        compile_ahead(confirm, screen.traces)
        screen.reference_for(current, settings)
        cv_sub = screen.info["loeo_rss_bar2"]
        passed = []
        for s in confirm:
            _say(settings, f"screening refit with {s.effect} (score {s.statistic:.1f})")
            fit = screen_refit(s, current, screen, settings)
            refits[s.effect] = s.refit
            if fit is not None and _qualifies(s.refit, cv_sub):
                passed.append((s, fit))
        passed = [passed[i] for i in by_criterion([p[0].refit for p in passed])]
        sub_fit = screen_settings(settings)
        for s, fit in passed:
            if not alternatives_beaten(s, "screening", screen.traces, screen.reference, sub_fit):
                continue
            rss_ref, cv_ref = full_reference()
            _say(settings, f"confirming {s.effect} on all {len(train)} training experiments")
            state = _confirm(s, current, rss_ref, train, test, settings, screened=fit)
            refits[s.effect] = s.refit
            if state is not None:
                states[s.effect] = state
                if _qualifies(s.refit, cv_ref):
                    break

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
        if screen is None:
            confirm_all(confirm)
        else:
            screen_then_confirm(confirm)
        confirmed = [s for s in significant if s.effect in states]
        if screen is not None and not confirmed:
            if matched:
                return None, _matched_decision(matched, "screening subset")
            screened = [s.refit for s in significant if "delta_bic" in s.refit]
            if any(r["delta_bic"] < 0 for r in screened):
                return None, "no leave-one-experiment-out improvement (screening subset)"
            return None, "information criterion did not improve (screening subset)"
        ok = [s for s in confirmed if s.refit["delta_bic"] < 0]
        if not ok:
            return None, "information criterion did not improve"
        _, cv_ref = full_reference()
        ok = [s for s in ok if _qualifies(s.refit, cv_ref)]
        if not ok:
            return None, "no leave-one-experiment-out improvement"
        ok = [ok[i] for i in by_criterion([s.refit for s in ok])]
        if screen is not None:  # the alternatives were refitted on the subset already
            return ok[0], "added"
        for s in ok:
            if alternatives_beaten(s, "all training experiments", train, ref[0], None):
                return s, "added"
        return None, _matched_decision(matched, "all training experiments")

    try:  # the refits run in attempt(): where the discovery's time budget can stop it
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
            check_budget("the refits after the profile look")
            chosen, again = attempt(scores)
            decision = decision if again == "no new candidate" else again
    except DiscoveryTimeLimit as stop:
        return stopped(stop, scores)
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


@quiet_design_checks  # its probes and refits are not the user's values
def discover(
    dataset: Dataset | list[Trace],
    model: CircuitModel | None = None,
    settings: DiscoverySettings | None = None,
    start: ParameterSet | None = None,
    baseline: FitResult | None = None,
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
    baseline : FitResult, optional
        A fit of ``model`` already made on exactly the training experiments (e.g. the
        ``physics_fitted`` variant's, or ``clutchlab fit-physics``'s JSON): it is the
        starting model and the baseline fit is not repeated. Its structure may hold more
        than ``model`` (flexible laws the fit's staged start switched on).

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
    if baseline is not None:
        _check_baseline(baseline, model, train)
    prefit: list = []  # the baseline fit's pre-fit optimum, when this discovery fits it
    with discovery_budget(settings.time_limit_s, t_start):
        if baseline is None:
            what = model.effect_names or "the base model"
            _say(settings, f"fitting {what} on {len(train)} experiments")
            free0 = resolve_free(model, settings.fit)
            baseline = run_fit(
                model,
                train,
                settings,
                free0,
                start,
                what="the baseline fit",
                budget_ok=True,
                prefit=prefit,
            )
        else:
            _say(settings, f"starting from the given fit ({baseline.status})")
        current = _state(baseline, train, test, settings, jacobian=False)
        baseline = current
        iterations: list[IterationRecord] = []
        for index in range(settings.max_effects + 1):
            own = prefit[0] if prefit and not iterations else None
            record = _iteration(index, current, pool, train, test, settings, len(iterations), own)
            iterations.append(record)
            if record.effect is None:
                break
            current = record.after
    final_diag = diagnose(current.residual, settings.max_lag_s)
    last = iterations[-1]
    # "Unexplained" needs structure that follows an examined signal: a residual that is
    # not white but follows none of them (line-pressure wander, noise) names nothing; and a
    # look that the time budget cut short does not get to call anything unexplained.
    structured = not final_diag.whiteness.get("white", True)
    follows = bool(final_diag.signature) and not last.time_limited
    unexplained = last.effect is None and bool(last.candidates) and structured and follows
    signature = final_diag.signature if unexplained else []
    summary = _summary(iterations, unexplained, final_diag, settings.fit.substeps)
    if last.time_limited:
        fit, added = current.fit, [it.effect for it in iterations if it.effect]
        had = (
            f"the model is the one it had ({', '.join(added)} added)"
            if added
            else f"the model is its baseline fit ({fit.status}"
            + ("" if fit.success else ", not converged")
            + ")"
        )
        message = f"discovery: {last.decision}; {had}"
        warn_at_caller(message, FitWarning)  # the user's line, not the wrapper's
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
        time_limited=last.time_limited,
    )


def _check_baseline(baseline: FitResult, model: CircuitModel, train: list[Trace]) -> None:
    """Refuse a given baseline fit made on other experiments or without ``model``'s effects."""
    fitted, wanted = sorted(baseline.train), sorted(t.name for t in train)
    if fitted != wanted:
        raise FitError(
            "the given baseline fit was made on other experiments than the training ones: "
            f"fitted on {fitted}, training {wanted}"
        )
    missing = [e for e in model.effect_names if e not in baseline.effects]
    if missing:
        raise FitError(f"the given baseline fit lacks the model's effect(s) {missing}")


def _settings_dict(settings: DiscoverySettings) -> dict:
    d = asdict(settings)
    return {
        k: (list(v) if isinstance(v, tuple) else v)
        for k, v in d.items()
        if not isinstance(v, dict) or k != "fit"
    } | {"fit": {k: (list(v) if isinstance(v, tuple) else v) for k, v in d["fit"].items()}}


def _summary(iterations: list[IterationRecord], unexplained: bool, diag, substeps: int) -> str:
    added = [it for it in iterations if it.effect]
    parts = []
    for it in added:
        test = ""
        if math.isfinite(it.before.test["rmse_bar"]):  # no test experiments: nothing to say
            before, after = it.before.test["rmse_bar"], it.after.test["rmse_bar"]
            test = f", test-ramp RMSE {before:.4f} → {after:.4f} bar"
            if after > before:  # said, not hidden: the test ramp never decides a claim
                test += (
                    f" (worse on the unseen test ramp by {100 * (after / before - 1):.0f} %: "
                    "the claim rests on the training experiments left out one at a time"
                    + (
                        ""
                        if it.after.fit.success
                        else "; its refit stopped at a limit (see the fit status), more "
                        "--max-iter / --time-limit may change that"
                    )
                    + ")"
                )
        parts.append(
            f"added {it.effect} (ΔBIC {it.delta_bic:.1f}): training RMSE "
            f"{it.before.train['rmse_bar']:.4f} → {it.after.train['rmse_bar']:.4f} bar{test}"
        )
    last = iterations[-1]
    if unexplained:
        follows = ", ".join(diag.signature) or "no single signal"
        significant = [c.effect for c in last.candidates if c.significant]
        if significant:  # significant, but not claimed (a flexible law matched it …)
            verb = "explains" if len(significant) == 1 else "explain"
            parts.append(
                f"unexplained residual: {', '.join(significant)} {verb} a significant share "
                f"of it, but no effect is claimed ({last.decision}); it follows {follows}"
            )
        else:
            parts.append(
                "unexplained residual: no library effect explains a significant share of it "
                f"({last.decision}); it follows {follows}; no effect claimed for it"
            )
    elif last.time_limited:
        parts.append(f"{last.decision}; the rest of the search did not run")
    elif last.decision == "effect limit reached" and not added:
        parts.append("no effect was looked for (the effect limit is 0)")
    elif last.decision == "effect limit reached":
        parts.append("stopped at the effect limit; the remaining residual was not scored")
    elif last.effect is None and diag.whiteness.get("white", True):
        parts.append(f"stopped: {last.decision}; the remaining residual is white")
    elif last.effect is None:
        parts.append(
            f"stopped: {last.decision}; the remaining residual is not white but follows "
            "none of the examined signals"
        )
    if not added and not unexplained and last.decision != "effect limit reached":
        parts.insert(0, "no effect added" if last.time_limited else "no missing effect found")
    ramp = diag.ramp_note()
    if ramp and not diag.whiteness.get("white", True):
        parts.append(ramp)
    diverged = _diverged_note(last.candidates, substeps)
    if diverged:
        parts.append(diverged)
    return "; ".join(parts) + "."


def _diverged_note(scores, substeps: int) -> str:
    """Which candidates could not be simulated at some of their profile strengths."""
    where = []
    for s in scores:
        if s.diverged:
            points = ", ".join(" ".join(f"{k} = {v:.3g}" for k, v in p.items()) for p in s.diverged)
            where.append(f"{s.effect} at {points}")
    if not where:
        return ""
    return (
        "not evaluated where the model's integration diverged with "
        f"{substeps} substeps per sample: {'; '.join(where)} (more substeps may reach it: "
        "`--substeps`)"
    )
