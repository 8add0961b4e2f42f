"""Multi-experiment physics parameter estimation (CasADi sensitivities + IPOPT)."""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace

import numpy as np
from sklearn.exceptions import NotFittedError
from tqdm.auto import tqdm

from ...data import (
    Dataset,
    Trace,
    as_traces,
    dither_period_mean,
    dither_period_samples,
    pressure_metrics,
)
from ...errors import DataError, FitError, FitWarning, ModelError, warn_at_caller
from ...forkmap import fork_map
from ..effects import EFFECTS, missing_effect
from ..effects.flexible import switched_on
from ..model import CircuitModel
from ..parameters import ParameterSet, quiet_design_checks
from ..settings import SimulationSettings
from ..simulate import simulate
from .latch_band import BAND_FINISH_S, BAND_RESERVE_S, band_asked, latch_band_structure
from .latch_lag import latch_lag_structure
from .latch_rate import latch_rate_structure
from .nlp import COST_PLATEAU, ITERATION_LIMIT, WALL_TIME_LIMIT, solve_ipopt
from .problem import FitProblem
from .rate import at_fit_rate
from .result import FitResult, ParameterUncertainty, parameter_uncertainty, training_rms
from .sensitivity import compile_sensitivities_for
from .settings import DEFAULT_FREE, FitSettings
from .staged import (
    free_latch_structure,
    latch_port_structure,
    match_latch_snaps,
    regulator_lag_structure,
    staged_start,
)
from .stages import prefit_settings, prefit_subset, refine_settings

__all__ = ["PhysicsFitter", "PrefitPoint", "check_savable", "period_mean_pairs", "resolve_free"]

_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level", COST_PLATEAU)
#: Share of the time limit the solver stages may use; the rest is kept for the result (the
#: Jacobian at the optimum when the solver stopped at its limit, the per-experiment errors:
#: ~3 s on two processes for the default training set) and for the prediction error of the
#: solver's last iteration.
SOLVER_TIME_FRACTION = 0.88
#: Status of a stage the fit did not start: not enough time left for one iteration of it.
SHORT_OF_TIME = "Not_Started_Short_Of_Time"
#: Share of the time limit the staged start's latch-snap matching may use.
LATCH_MATCH_TIME_FRACTION = 0.1


def resolve_free(model: CircuitModel, settings: FitSettings) -> tuple[str, ...]:
    """The free parameters: the settings' list, or the defaults plus each effect's fit set."""
    known = [p.name for p in model.parameters]
    if settings.free is not None:
        free = tuple(settings.free)
    else:
        free = tuple(n for n in DEFAULT_FREE if n in known)
        for e in model.effects:
            free += tuple(n for n in EFFECTS[e.name].fit_parameters() if n not in free)
    unknown = [n for n in (*free, *settings.per_experiment) if n not in known]
    if unknown:
        missing = {n: missing_effect(n) for n in unknown}
        hints = "".join(
            f"; {n} {m[1]} (add it: --effects {m[0]}, or CircuitModel().with_effects({m[0]!r}))"
            for n, m in missing.items()
            if m is not None
        )
        raise FitError(
            f"unknown parameter(s) {', '.join(unknown)}{hints}; the model has: {', '.join(known)}"
        )
    missing = [n for n in settings.per_experiment if n not in free]
    if missing:
        raise FitError(f"per-experiment parameter(s) not free: {', '.join(missing)}")
    if not free:
        raise FitError("no free parameters")
    return free


def _uncertainty_at(
    model, traces, shared, settings, fitted, ev=None, problem=None
) -> ParameterUncertainty:
    """Standard errors and identifiability of ``shared`` at ``fitted`` from the
    single-shooting Jacobian on ``traces``: ``ev``'s (an evaluation of ``problem``) when
    it has one, else one pass."""
    if ev is None or ev.get("J") is None:
        ss_settings = {**asdict(settings), "method": "single_shooting", "per_experiment": ()}
        problem = FitProblem(model, traces, shared, FitSettings(**ss_settings), fitted)
        problem.start_workers(traces, settings.workers)
        try:
            ev = problem.evaluate(np.zeros(problem.n_z), True)
        finally:
            problem.close()
    specs = {p.name: p for p in model.parameters}
    if ev.get("J") is not None:
        blocks = [(s.row0, len(s.rows)) for s in problem.segments]
        return parameter_uncertainty(
            ev["J"].toarray(), ev["r"], list(shared), specs, fitted, blocks
        )
    return ParameterUncertainty({}, [], [], list(shared), [])


def _model_fields(model, fitted, unc: ParameterUncertainty, std_errors: dict) -> dict:
    """A fit result's fields that follow from its model, values and uncertainty."""
    return {
        "effects": list(model.effect_names),
        "values": dict(fitted.values),
        "units": {p.name: p.unit for p in model.parameters},
        "std_errors": std_errors,
        "correlation": unc.correlation,
        "singular_values": unc.singular_values,
        "unidentifiable": unc.unidentifiable,
        "weak_directions": unc.weak_directions,
        "residual_correlation_time": unc.correlation_time,
    }


def _stopped_by_time(best: dict) -> bool:
    """The solver of this best start stopped at its wall-time limit."""
    stats = best["stats"]
    return stats is not None and stats["return_status"] == WALL_TIME_LIMIT


def period_mean_pairs(
    model: CircuitModel,
    params: list[ParameterSet],
    traces: list[Trace],
    workers: int,
    sim: SimulationSettings | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per trace, the measured and simulated dither-period-mean clutch pressure (bar).

    Parameters
    ----------
    model : CircuitModel
        Model structure.
    params : list of ParameterSet
        One parameter set per trace (engineering units).
    traces : list of Trace
        Experiments.
    workers : int
        Forked processes simulating the traces where the platform has fork (the same
        numbers with any number), else this process.
    sim : SimulationSettings, optional
        Simulation settings; the defaults (as every scored ramp) when None.

    Returns
    -------
    list of (numpy.ndarray, numpy.ndarray)
        ``(measured, simulated)`` per trace, in the order of ``traces``.
    """
    sim = sim or SimulationSettings()

    def pair(e: int) -> tuple[np.ndarray, np.ndarray]:
        tr = traces[e]
        n = dither_period_samples(tr)
        pred = simulate(model, params[e], tr, sim).pressure_bar
        return dither_period_mean(tr.get("clutch_pressure_bar"), n), dither_period_mean(pred, n)

    # longest first, so that the processes end together
    order = sorted(range(len(traces)), key=lambda e: -len(traces[e]))
    return fork_map(pair, len(traces), workers, order)


def _per_experiment_metrics(
    model: CircuitModel, params: list[ParameterSet], traces: list[Trace], workers: int
) -> dict[str, dict[str, float]]:
    """Each training experiment's RMSE (bar) and fit (%) of the fitted model, dither-period
    means, simulated on ``workers`` forked processes where the platform has fork (the fit's
    last seconds: ~5 s for the default training set on one core), else in this process."""
    rows = {}
    for tr, (y, yh) in zip(traces, period_mean_pairs(model, params, traces, workers), strict=True):
        m = pressure_metrics(y, yh)
        rows[tr.name] = {"rmse_bar": m["rmse_bar"], "fit_pct": m["fit_pct"]}
    return rows


def check_savable(model: CircuitModel) -> None:
    """ModelError when ``model`` has components a saved fit or physics file cannot record.

    Parameters
    ----------
    model : CircuitModel
        The fitted model.

    Raises
    ------
    ModelError
        Naming the custom components and what to save instead.
    """
    custom = model.custom_components()
    if custom:
        raise ModelError(
            f"cannot save a model with components other than the base circuit's "
            f"({'; '.join(custom)}): the file records the effects and parameter values only, "
            "and loading it would build the base circuit, which predicts differently; save "
            "the values (fitter.params_.to_json(path)) and rebuild the model in code"
        )


@dataclass(frozen=True)
class PrefitPoint:
    """Where a staged fit's pre-fit ended: its optimum on the pre-fit subset.

    Attributes
    ----------
    model : CircuitModel
        The model fitted (the structure of the refinement that followed).
    experiments : tuple of str
        Names of the subset's experiments, in pick order.
    params : ParameterSet
        The pre-fit's best iterate (engineering units).
    status : str
        The pre-fit's solver status.
    """

    model: CircuitModel
    experiments: tuple[str, ...]
    params: ParameterSet
    status: str


class PhysicsFitter:
    """Fit the circuit model's parameters to test-stand data.

    scikit-learn contract: ``__init__`` stores its arguments, :meth:`fit` validates
    and returns ``self``; learned state ends in ``_`` (``result_``, ``params_``,
    ``model_``; ``staged_``, the staged start's record; ``prefit_``, the
    :class:`PrefitPoint` of a fit staged into a pre-fit and a refinement, else None);
    :meth:`predict` before :meth:`fit` raises ``NotFittedError``.

    Parameters
    ----------
    model : CircuitModel, optional
        Model structure (effects on); the base circuit by default.
    settings : FitSettings, optional
        Free parameters, method, objective, limits.
    start : ParameterSet, optional
        Starting values (and fixed values), engineering units; the datasheet defaults by
        default, with the held switches among ``model``'s flexible laws on (``rlag_w``,
        ``lsel_w`` at 1: :func:`~clutchlab.physics.effects.flexible.switched_on`; at their
        default 0 they would act on nothing). It must be a set of ``model``'s parameters
        (``model.params(...)``): one built for another model makes :meth:`fit` raise
        ``FitError`` naming the missing and extra parameters; it is used as given.

    Notes
    -----
    Objective: ``½ Σ (P̄_model − P̄_measured)²`` over the training experiments, with
    ``P̄`` the pressure averaged over one dither period (bar), every ``decimate``-th
    sample. Standard errors come from the Gauss–Newton Fisher information of a
    single-shooting pass at the optimum, with the residual variance estimated from
    the fit; neighbouring residuals are correlated by the period mean, so they are
    lower bounds of the true uncertainty.
    """

    def __init__(
        self,
        model: CircuitModel | None = None,
        settings: FitSettings | None = None,
        start: ParameterSet | None = None,
    ) -> None:
        self.model = model
        self.settings = settings
        self.start = start

    def __repr__(self) -> str:
        # as scikit-learn's: the constructor arguments that were given
        given = [(k, getattr(self, k)) for k in ("model", "settings", "start")]
        return f"PhysicsFitter({', '.join(f'{k}={v!r}' for k, v in given if v is not None)})"

    # ---- validation ---------------------------------------------------------------
    def _check_arguments(self) -> None:
        """FitError naming a constructor argument of the wrong type (they failed inside the
        fit with an AttributeError such as "'dict' object has no attribute 'train_ramps'")."""
        problems = []
        for name, cls, hint in (
            ("model", CircuitModel, "CircuitModel().with_effects(...)"),
            ("settings", FitSettings, "FitSettings(**settings)"),
        ):
            value = getattr(self, name)
            if value is not None and not isinstance(value, cls):
                problems.append(
                    f"{name} must be a {cls.__name__} or None, not {type(value).__name__} ({hint})"
                )
        if problems:
            raise FitError("PhysicsFitter: " + "; ".join(problems))

    def _training(self, data) -> list[Trace]:
        settings = self.settings or FitSettings()
        if isinstance(data, Dataset):
            missing = [r for r in settings.train_ramps if r not in data.ramps]
            if missing:  # never train silently on fewer ramps than asked for
                raise FitError(
                    f"training ramp(s) {missing} not in the dataset (it has {data.ramps}); "
                    f"asked for {list(settings.train_ramps)}"
                )
            traces = list(data.select(ramps=[r for r in settings.train_ramps if r in data.ramps]))
        else:
            try:
                traces = as_traces(data, "training", arrays=False)
            except DataError as exc:  # a path, a mixed list, not experiments at all
                raise FitError(f"fit: {exc}") from None
        if not traces:
            raise FitError("no training experiments")
        problems = []
        for tr in traces:
            cur = tr.get("current_mA") if tr.has("current_mA") else tr.get("current_cmd_mA")
            span = float(np.ptp(cur))
            n = dither_period_samples(tr)
            p_span = float(np.ptp(dither_period_mean(tr.get("clutch_pressure_bar"), n)))
            if span < settings.min_current_span_mA:
                problems.append(
                    f"{tr.name}: no excitation — the current spans only "
                    f"{span:.1f} mA (< {settings.min_current_span_mA:g} mA)"
                )
            elif p_span < settings.min_pressure_span_bar:
                problems.append(
                    f"{tr.name}: no excitation — the pressure spans only "
                    f"{p_span:.3f} bar (< {settings.min_pressure_span_bar:g} bar)"
                )
        if problems:
            raise FitError("cannot fit:\n  - " + "\n  - ".join(problems))
        return traces

    def _own_start(self, model: CircuitModel) -> ParameterSet:
        """The user's start, checked to be a parameter set of ``model`` (ModelError if not)."""
        if not isinstance(self.start, ParameterSet):
            raise ModelError(
                f"start must be a ParameterSet (model.params(name=value, ...)), "
                f"not {type(self.start).__name__}"
            )
        effects = "effects " + ", ".join(model.effect_names) if model.effects else "no effects"
        try:
            return self.start.for_model(model.parameters, f"model {model.name!r} ({effects})")
        except ModelError as exc:
            raise ModelError(f"start: {exc}") from None

    @staticmethod
    def _check_bounds(model: CircuitModel, free, settings: FitSettings, start: ParameterSet):
        specs = {p.name: p for p in model.parameters}
        problems = []
        for n in free:
            p = specs[n]
            lb, ub = settings.bounds.get(n, (p.lower, p.upper))
            if not lb < ub:
                problems.append(f"{n}: lower bound {lb} ≥ upper bound {ub} {p.unit}")
            elif lb < p.lower or ub > p.upper:
                problems.append(
                    f"{n}: bounds [{lb}, {ub}] leave the physical range "
                    f"[{p.lower}, {p.upper}] {p.unit}"
                )
            elif not lb <= start[n] <= ub:
                problems.append(f"{n}: start value {start[n]} outside bounds [{lb}, {ub}] {p.unit}")
            elif p.transform == "log" and lb <= 0:
                problems.append(f"{n}: log-scaled parameter needs a positive lower bound")
        unknown = sorted(set(settings.bounds) - set(free))
        problems += [f"{n}: bounds given but the parameter is not free" for n in unknown]
        if problems:
            raise FitError("infeasible bounds:\n  - " + "\n  - ".join(problems))

    # ---- fit ----------------------------------------------------------------------------
    @quiet_design_checks  # its iterates and staged-start probes are not the user's values
    def fit(self, data: Dataset | Trace | list[Trace]) -> PhysicsFitter:
        """Estimate the free parameters on the training experiments of ``data``.

        Parameters
        ----------
        data : Dataset, Trace or list of Trace
            A dataset: its experiments of the ramps ``settings.train_ramps`` are fitted on.
            One trace, or a list of them: every one is fitted on, whatever its ramp.

        Returns
        -------
        PhysicsFitter
            ``self``, fitted (``result_``, ``params_``, ``model_``).

        Raises
        ------
        FitError
            Bad settings or bounds, a constructor argument or ``data`` of the wrong type (a
            path: load it with :func:`~clutchlab.data.load_dataset`), experiments without
            excitation, a model that diverges at the start, or a solver that fails or runs
            out of time (``exc.result`` then holds the best iterate found).
        """
        t_start = time.perf_counter()
        self._check_arguments()
        model = self.model or CircuitModel()
        settings = self.settings or FitSettings()
        try:
            if self.start is None:  # the datasheet values, with named switches on
                start = model.default_params().replace(**switched_on(model))
            else:
                start = self._own_start(model)
        except ModelError as exc:
            raise FitError(str(exc)) from exc
        traces = at_fit_rate(self._training(data), settings.fit_rate_Hz)
        free = resolve_free(model, settings)
        self._check_bounds(model, free, settings, start)
        self.staged_ = None
        self.prefit_ = None
        band_reserve_s = 0.0  # solver time kept for the latch band stage
        datasheet = (model, start, free)  # what the staged start starts from
        if settings.staged_start and self.start is None and not settings.per_experiment:
            # the main stages' Jacobian code compiles on the other core meanwhile
            self._compile_ahead(model, traces, free, settings)
            start, self.staged_ = staged_start(
                model,
                traces,
                settings,
                start,
                free,
                settings.static_time_fraction * settings.time_limit_s,
            )
            if (
                settings.latch_law == "auto"
                and self.staged_.latch_tie_violated
                and settings.free is None
            ):
                model, start = free_latch_structure(model, start, self.staged_)
                free = resolve_free(model, settings)
            match_s = LATCH_MATCH_TIME_FRACTION * settings.time_limit_s
            if self.staged_.regulator_lag_ms is not None and settings.free is None:
                model, start = regulator_lag_structure(model, start, self.staged_)
                free = resolve_free(model, settings)
                # a latch that does not see the regulated branch's lag: which port it switches
                model, start = latch_port_structure(
                    model, start, traces, free, settings, self.staged_, match_s
                )
            else:
                start = match_latch_snaps(
                    model, start, traces, free, settings, self.staged_, match_s
                )
            if settings.latch_band != "off" and settings.free is None:
                # whether the fit keeps time for the latch band after the solver: the
                # staged start's own snaps ask for it, or the line law is offered
                # (latch_band.py)
                if band_asked(model, start, traces, free, settings, self.staged_):
                    band_reserve_s = BAND_RESERVE_S
        history: list[float] = []
        bar = tqdm(
            total=settings.max_iter,
            desc="fit-physics",
            unit="it",
            disable=not settings.progress,
            leave=False,
        )

        def on_jacobian(cost):
            history.append(cost)
            bar.update(1)
            bar.set_postfix(cost=f"{cost:.4g}", best=f"{min(history):.4g}")

        z_par = None
        kept = None  # (problem, best) of the last stage that produced an iterate
        statuses: list[str] = []
        # per stage that produced an iterate: its cost at its own start (its first
        # Jacobian) and at its best; stages fit different experiments, so costs are
        # compared within a stage only
        stage_costs: list[tuple[float, float]] = []
        cost_stages: list[int] = []  # the stage of each entry of stage_costs
        stages = self._stages(traces, settings)
        # the rest of the limit is kept for the result (and the latch band stage)
        solver_deadline = t_start + SOLVER_TIME_FRACTION * settings.time_limit_s - band_reserve_s
        sample_s = None  # wall time of one iteration per sample, measured on the last stage
        try:
            for stage, (stage_traces, stage_settings) in enumerate(stages):
                n_samples = sum(len(t) for t in stage_traces)
                # A stage that cannot even take its first Jacobian (one iteration of the
                # previous stage per sample, scaled to this one) is not started; one that
                # can is, as that Jacobian also gives the result's standard errors. Within
                # a stage the solver starts no iteration it cannot finish (nlp.py).
                first = 0.0 if sample_s is None else sample_s * n_samples
                left = solver_deadline - time.perf_counter()
                if stage > 0 and left < first:
                    statuses.append(SHORT_OF_TIME)
                    break
                t_stage = time.perf_counter()
                h0 = len(history)
                bar.set_description(f"fit-physics ({len(stage_traces)} exp)")
                problem = FitProblem(model, stage_traces, free, stage_settings, start)
                problem.on_jacobian = on_jacobian
                starts = [np.zeros(problem.n_par) if z_par is None else z_par]
                if stage == 0:
                    starts += self._multistarts(problem, settings)
                # compiled once, here, before the workers fork (a one-off: not part of
                # the per-sample iteration time that plans the next stage)
                t_compile = time.perf_counter()
                problem.compile_jacobian_code()
                t_stage += time.perf_counter() - t_compile
                problem.start_workers(stage_traces, settings.workers)
                try:
                    best = self._solve_starts(problem, starts, stage_settings, solver_deadline)
                    if best["z"] is not None and _stopped_by_time(best):
                        # The result's standard errors need the Jacobian at this iterate,
                        # which a solver stopped mid-way has not computed: on the workers.
                        problem.evaluate(best["z"], True)
                finally:
                    problem.close()
                n_iter = max(problem.n_jac_evals, 1)
                sample_s = (time.perf_counter() - t_stage) / n_iter / n_samples
                # No start of this stage ran when the time limit was reached before it.
                statuses.append(
                    best["stats"]["return_status"] if best["stats"] is not None else WALL_TIME_LIMIT
                )
                if best["z"] is not None:
                    z_par = best["z"][: problem.n_par]
                    kept = (problem, best)
                    if stage == 0 and len(stages) > 1:
                        self.prefit_ = PrefitPoint(
                            model,
                            tuple(t.name for t in stage_traces),
                            problem.parameter_set(best["z"], 0),
                            statuses[-1],
                        )
                    stage_costs.append(
                        (history[h0] if len(history) > h0 else math.inf, best["cost"])
                    )
                    cost_stages.append(stage)
                elif kept is not None:  # keep the previous stage's iterate, not the start
                    problem, best = kept
                if len(stages) > 1 and stage == 0 and statuses and statuses[0] not in _OK:
                    break  # the pre-fit failed: do not polish a failure
        finally:
            bar.close()
        result = self._result(
            model, problem, best, history, traces, settings, time.perf_counter() - t_start
        )
        if band_reserve_s and best["z"] is not None:
            result = self._with_latch_band(result, problem, traces, settings, t_start)
        # A refinement stopped by its iteration limit after a converged pre-fit is a
        # finished fit: the limit is the refinement's budget, not a failure.
        converged = bool(statuses) and (
            statuses[-1] in _OK
            or (
                len(stages) > 1
                and len(statuses) == 2
                and statuses[0] in _OK
                and statuses[1] == ITERATION_LIMIT
            )
        )
        if len(stages) > 1:
            result.status = " → ".join(
                f"{st} ({lbl})" for st, lbl in zip(statuses, ("pre-fit", "refine"), strict=False)
            )
        result.success = converged
        if not converged:
            status = result.status if statuses else "no start completed"
            # improved on its start: some stage ended below where it started (each stage
            # starts from the previous one's best)
            improved = best["z"] is not None and any(b < a for a, b in stage_costs)
            start_cost = stage_costs[-1][0] if stage_costs else math.inf
            # No solver stage got below its start, but the staged start (the static
            # characteristic and the latch from the data) may have got below the datasheet
            # values: then the model is the staged start, as good a best iterate as any
            staged_gain = None
            if not improved and self.staged_ is not None and best["z"] is not None:
                stage_traces, stage_settings = stages[cost_stages[0]]
                staged_gain = _staged_start_gain(
                    *datasheet, stage_traces, stage_settings, stage_costs[0][0]
                )
                improved = staged_gain is not None
            wall = time.perf_counter() - t_start
            if settings.strict or not improved:
                why = "" if improved else " and did not improve on its start"
                best_text = (
                    f"best cost {best['cost']:.6g} bar²"
                    if math.isfinite(best["cost"])
                    else "no iteration finished, so the start is the best iterate"
                )
                err = FitError(
                    f"the fit did not converge ({status}){why} after {wall:.1f} s; {best_text}"
                )
                err.result = result
                raise err
            if staged_gain is None:
                what = (
                    f"its best iterate (cost ½Σe² {best['cost']:.6g} bar², {start_cost:.6g} at "
                    "the start of its stage) is the model"
                )
            else:
                what = result.note = (
                    "the solver did not get below the staged start, which had lowered the "
                    f"cost ½Σe² on the {staged_gain[2]} experiment(s) of its first stage from "
                    f"{staged_gain[0]:.6g} bar² (datasheet values) to {staged_gain[1]:.6g}: "
                    "the staged start is the model"
                )
            warn_at_caller(  # the user's line, not the quiet-checks wrapper's
                f"the fit stopped at a limit before converging ({status}) after {wall:.1f} s: "
                f"{what}, marked not converged",
                FitWarning,
            )
        self.result_ = result
        self.model_ = result.model()
        self.params_ = result.params()
        return self

    @staticmethod
    def _compile_ahead(model, traces, free, settings) -> None:
        """Start compiling the Jacobian code of the fit's stages in the background (the
        staged start runs in this process meanwhile). Single shooting only (its code has
        one direction per free parameter); a model the staged start changes needs other
        code, compiled when its stage starts."""
        if settings.method == "single_shooting":
            compile_sensitivities_for(
                model, traces, settings.substeps, settings.drive, len(free), background=True
            )

    @staticmethod
    def _stages(traces: list[Trace], settings: FitSettings):
        """The fit's stages: a pre-fit on a subset when the data exceed ``prefit_samples``,
        then a short refinement on every training experiment (see :mod:`.stages`)."""
        budget = settings.prefit_samples
        if settings.per_experiment or not budget or sum(len(t) for t in traces) <= budget:
            return [(traces, settings)]
        subset = prefit_subset(traces, budget)  # may be all of them (each ramp's first)
        return [(subset, prefit_settings(settings)), (traces, refine_settings(settings))]

    @staticmethod
    def _multistarts(problem: FitProblem, settings: FitSettings) -> list[np.ndarray]:
        """Latin-hypercube starts inside the parameter bounds (scaled space)."""
        n = settings.multistart
        if n <= 0:
            return []
        lo, hi = problem.bounds_z()
        rng = np.random.default_rng(settings.seed)
        cells = np.stack([rng.permutation(n) for _ in range(problem.n_par)])
        frac = (cells + rng.random(cells.shape)) / n
        return [lo + (hi - lo) * np.clip(frac[:, k], 0.02, 0.98) for k in range(n)]

    @staticmethod
    def _solve_starts(problem, starts, settings, deadline):
        """Run IPOPT from each start until ``deadline`` (``time.perf_counter()``, s); keep
        the lowest cost."""
        lo, hi = problem.bounds_z()
        slo, shi = problem.state_bounds()
        lbz, ubz = np.concatenate([lo, slo]), np.concatenate([hi, shi])
        best = {"cost": np.inf, "z": None, "stats": None}
        for z_par in starts:
            z0 = problem.initial_z(z_par)
            if not np.isfinite(problem.cost(z0)):
                raise FitError(
                    "the model diverges at the start parameters on "
                    f"{[e.name for e in problem.experiments]}"
                )
            # The rest of the limit is kept for the result (per-experiment errors,
            # uncertainty pass), so the whole fit stays within its limit.
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                break
            try:
                z, stats = solve_ipopt(
                    problem,
                    z0,
                    lbz,
                    ubz,
                    settings.max_iter,
                    settings.tol,
                    remaining,
                    settings.ipopt_options,
                    plateau=(
                        (settings.plateau_iter, settings.prefit_obj_change_tol)
                        if settings.plateau_iter
                        else None
                    ),
                )
            except RuntimeError as exc:  # a callback raised: keep what we have
                z, stats = z0, {"return_status": f"error: {exc}", "iter_count": 0, "success": False}
            # no iteration: the start itself (whose Jacobian the solver has computed), not
            # the start after IPOPT's push off the bounds
            z = np.clip(z0 if stats["iter_count"] == 0 else z, lbz, ubz)
            cost = problem.cost(z)
            if cost < best["cost"]:
                best = {"cost": cost, "z": z, "stats": stats}
        return best

    def _result(self, model, problem: FitProblem, best, history, traces, settings, wall):
        z = best["z"] if best["z"] is not None else problem.initial_z()
        fitted = problem.parameter_set(z, 0)
        free = list(problem.free)
        # Uncertainty and identifiability from the single-shooting Jacobian at the optimum:
        # the last stage's (cached) when it is single shooting on all experiments, else
        # one extra single-shooting pass — unless the fit's time is nearly spent: then the
        # last stage's subset (larger, i.e. conservative, standard errors).
        short_of_time = wall > 0.7 * settings.time_limit_s
        reuse = (
            not problem.ms
            and not problem.per_exp
            and (len(problem.experiments) == len(traces) or short_of_time)
            and best["z"] is not None
        )
        ev = problem.evaluate(best["z"], True) if reuse else None
        unc = _uncertainty_at(model, traces, tuple(problem.shared), settings, fitted, ev, problem)
        se = dict(unc.std_errors)
        for n in problem.per_exp:
            se[n] = float("nan")
        per_values = (
            {ex.name: problem.params_of(z, e)[1] for e, ex in enumerate(problem.experiments)}
            if problem.per_exp
            else {}
        )
        params = [problem.parameter_set(z, e) for e in range(len(traces))]
        per_exp = _per_experiment_metrics(model, params, traces, settings.workers)
        stats = best["stats"] or {"return_status": "not run", "iter_count": 0}
        return FitResult(
            **_model_fields(model, fitted, unc, se),
            free=free,
            per_experiment=per_exp,
            per_experiment_values=per_values,
            cost_history=list(history),
            status=stats["return_status"],
            success=stats["return_status"] in _OK,
            iterations=stats["iter_count"],
            wall_s=wall,
            train=[t.name for t in traces],
            settings={
                k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(settings).items()
            },
            uncertainty_note=unc.note,
        )

    def _with_latch_band(self, result, problem, traces, settings, t_start) -> FitResult:
        """The fit's result with the latch stages after the solver: the latch band stage
        (``latch_band.py``: ``latch_dither_band`` held at the values the quasi-static snaps
        give, the latch thresholds matched with it), then the latch rate stage
        (``latch_rate.py``: ``latch_rate_band`` at the values the faster ramps' snaps give),
        then the latch lag stage (``latch_lag.py``: the latch re-matched to the slow and fast
        snaps, with ``latch_on_lag`` where they ask); each kept only when its training RMS
        (over experiments) is lower than without it.
        Runs within the time the solver left it."""
        model, params = result.model(), result.params()
        per_exp, before = result.per_experiment, training_rms(result.per_experiment)
        kept = False
        stages = (
            ("latch band", "", latch_band_structure),
            ("latch rate band", "rate_", latch_rate_structure),
            ("latch lag", "lag_", latch_lag_structure),
        )
        for what, key, stage in stages:
            budget = settings.time_limit_s - (time.perf_counter() - t_start) - BAND_FINISH_S
            new_model, new_params = stage(
                model, params, traces, tuple(result.free), settings, self.staged_, budget
            )
            if new_model is model and new_params is params:
                continue
            new_exp = _per_experiment_metrics(
                new_model, [new_params] * len(traces), traces, settings.workers
            )
            after = training_rms(new_exp)
            self.staged_.latch_band.update(
                {f"{key}training_rms_before_bar": before, f"{key}training_rms_after_bar": after}
            )
            if not after < before:
                self.staged_.notes.append(
                    f"{what} not kept: training RMS {after:.4f} bar with it, {before:.4f} without"
                )
                continue
            self.staged_.notes.append(f"{what} kept: training RMS {before:.4f} → {after:.4f} bar")
            model, params, per_exp, before, kept = new_model, new_params, new_exp, after, True
        if not kept:  # the stages' time is the fit's all the same
            return replace(result, wall_s=time.perf_counter() - t_start)
        # (no per-experiment parameters here: the stages need the staged start, which
        # does not run with them)
        unc = _uncertainty_at(model, traces, tuple(problem.shared), settings, params)
        return replace(
            result,
            **_model_fields(model, params, unc, dict(unc.std_errors)),
            per_experiment=per_exp,
            wall_s=time.perf_counter() - t_start,
            uncertainty_note=unc.note,
        )

    # ---- use --------------------------------------------------------------------------
    def _check_fitted(self) -> None:
        if not hasattr(self, "result_"):
            raise NotFittedError("this PhysicsFitter is not fitted yet; call fit(dataset) first")

    def predict(self, trace: Trace, settings: SimulationSettings | None = None) -> np.ndarray:
        """Clutch pressure (bar) of the fitted model on ``trace``."""
        self._check_fitted()
        return simulate(self.model_, self.params_, trace, settings).pressure_bar

    def training_metrics(
        self, data: Dataset | Trace | list[Trace], params: ParameterSet | None = None
    ) -> dict[str, dict[str, float]]:
        """Each training experiment's RMSE (bar) and fit (%) of the dither-period-mean clutch
        pressure, as the fit result's ``per_experiment``.

        Parameters
        ----------
        data : Dataset, Trace or list of Trace
            As for :meth:`fit` (its training experiments are scored).
        params : ParameterSet, optional
            Values of the fitted model's parameters (e.g. the fit's start); the fitted
            values by default.

        Returns
        -------
        dict
            ``experiment name -> {"rmse_bar": …, "fit_pct": …}``.
        """
        self._check_fitted()
        settings = self.settings or FitSettings()
        traces = at_fit_rate(self._training(data), settings.fit_rate_Hz)
        values = [params if params is not None else self.params_] * len(traces)
        return _per_experiment_metrics(self.model_, values, traces, settings.workers)

    def save(self, path) -> None:
        """Write the fit result as JSON.

        Parameters
        ----------
        path : str or Path
            The JSON file (written atomically).

        Raises
        ------
        NotFittedError
            If the fitter is not fitted.
        ModelError
            If the fitted model has components other than the base circuit's: the file
            records the effects and values only, and :meth:`load` would rebuild the base
            circuit, which predicts differently.
        """
        self._check_fitted()
        check_savable(self.model_)
        self.result_.to_json(path)

    @classmethod
    def load(cls, path) -> PhysicsFitter:
        """A fitted fitter from a JSON written by :meth:`save`."""
        result = FitResult.from_json(path)
        fitter = cls(result.model())
        fitter.result_ = result
        fitter.model_ = result.model()
        fitter.params_ = result.params()
        return fitter


def _staged_start_gain(
    model: CircuitModel,
    start: ParameterSet,
    free: tuple[str, ...],
    traces: list[Trace],
    settings: FitSettings,
    staged_cost: float,
) -> tuple[float, float, int] | None:
    """(datasheet cost, staged-start cost, experiments) on one stage's experiments when the
    staged start lowered the cost ½Σe² (bar²) below the datasheet values', else None.

    One simulation of ``traces`` (this process) at the datasheet values; a model that
    diverges there counts as the highest cost.
    """
    if not math.isfinite(staged_cost):
        return None
    try:
        problem = FitProblem(model, traces, free, settings, start)
        datasheet_cost = problem.cost(problem.initial_z())
    except FitError:  # the integrator diverges at the datasheet values
        datasheet_cost = math.inf
    if not datasheet_cost > staged_cost:
        return None
    return datasheet_cost, staged_cost, len(traces)
