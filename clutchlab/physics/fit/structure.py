"""Choice of the fit model's structure (which flexible laws) inside the training set.

Each candidate structure (a set of effects / flexible component laws on the base
circuit) is fitted to the training experiments; the one with the lowest Bayesian
information criterion on the training residuals is the model's structure. Nothing
outside the training ramps is seen: the test ramp (medium) plays no part.

The criterion works on the dither-period-mean pressure residuals (bar) of the
training experiments, one value per dither period (neighbouring samples of a
period mean repeat each other). Those residuals are still serially correlated, so
the sample count in the criterion is an *effective* one,
``n_eff = Σ_e m_e (1 − ρ_e)/(1 + ρ_e)`` (AR(1) correction; ``m_e`` periods and
``ρ_e`` the lag-one autocorrelation of experiment ``e``'s residual, taken from the
candidate with the smallest residual, the best available picture of the error
process), the same for every candidate:

``BIC = n_eff · ln(RSS / m) + k · ln(n_eff)``

with ``RSS / m`` the mean squared period-mean residual and ``k`` the number of free
parameters. A flexible law must therefore buy a residual reduction worth its
parameters at the data's effective information, not at its sample count.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ...data import (
    Dataset,
    Trace,
    dither_period_mean,
    dither_period_samples,
    write_file_atomic,
)
from ...errors import FitError, ModelError
from ..components.latch import latch_thresholds
from ..effects import FLEXIBLE_LAWS
from ..model import CircuitModel
from ..simulate import simulate
from .fitter import PhysicsFitter, resolve_free
from .result import FitResult
from .settings import FitSettings

__all__ = [
    "DEFAULT_CANDIDATES",
    "STRUCTURES",
    "CandidateScore",
    "StructureSelection",
    "StructureSelector",
    "effective_sample_size",
    "information_criterion",
    "select_structure",
    "structure_effects",
]

#: Named candidate structures: the flexible laws each adds to the base circuit.
STRUCTURES: dict[str, tuple[str, ...]] = {
    "plain": (),
    "force": ("vfs_force_monotone",),
    "play": ("vfs_play_hysteresis",),
    "latch": ("latch_free_thresholds",),
    "vfs": ("vfs_force_monotone", "vfs_play_hysteresis"),
    # the held switches (reg_pilot_lag, latch_line_select, latch_pilot_lag) are no
    # candidates: the first two are switched on by the staged start's lag signature
    # (FitSettings.regulator_lag), the third is discovery's alternative; at their default
    # weight 0 they act on nothing.
    # (nor the laws added to a fit already made only, WARM_ONLY: latch_dither_band)
    "flex": tuple(n for n, law in FLEXIBLE_LAWS.items() if not (law.HELD_SWITCH or law.WARM_ONLY)),
}

#: Candidates compared by default: the datasheet form and each flexible law alone
#: (all three at once, ``flex``, 15 free parameters, ran off its start on the stand
#: within a 200 s limit; see the candidate fallback in :class:`StructureSelector`).
DEFAULT_CANDIDATES: tuple[str, ...] = ("plain", "force", "play", "latch")

#: Bound of the lag-one autocorrelation in the effective sample size (-).
_RHO_MAX = 0.99


def structure_effects(name: str) -> tuple[str, ...]:
    """The flexible laws of the named structure.

    Raises
    ------
    ModelError
        For an unknown structure name (the message lists the known ones).
    """
    try:
        return STRUCTURES[name.strip()]
    except KeyError:
        known = ", ".join(STRUCTURES)
        raise ModelError(f"unknown structure {name!r}; known structures: {known}") from None


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(r))))


def _period_residuals(trace: Trace, predicted: np.ndarray) -> np.ndarray:
    """Period-mean residual (bar), one value per dither period of ``trace``."""
    n = dither_period_samples(trace)
    r = dither_period_mean(predicted, n) - dither_period_mean(trace.get("clutch_pressure_bar"), n)
    step = max(1, round(n))
    return np.asarray(r[step // 2 :: step], dtype=float)


def _warm_start(model: CircuitModel, values: dict[str, float]):
    """Start values of ``model`` from a fit of the structure without flexible laws.

    The flexible laws start at their identity setting (their defaults); free latch
    thresholds start at the thresholds of the fitted latch spring.
    """
    known = {p.name for p in model.parameters}
    start = {k: v for k, v in values.items() if k in known}
    if "lthr_p_on" in known and "latch_F0" in values:
        p_on, p_off = latch_thresholds(values)
        start.update(lthr_p_on=p_on, lthr_p_off=p_off)
    specs = {p.name: p for p in model.parameters}
    start = {k: min(max(v, specs[k].lower), specs[k].upper) for k, v in start.items()}
    return model.params(**start)


def effective_sample_size(residuals: list[np.ndarray]) -> float:
    """AR(1) effective number of independent residuals, summed over experiments.

    Parameters
    ----------
    residuals : list of ndarray
        One residual series (bar, one value per dither period) per experiment.

    Returns
    -------
    float
        ``Σ_e m_e (1 − ρ_e)/(1 + ρ_e)`` with ``ρ_e ∈ [0, 0.99]`` the lag-one
        autocorrelation of series ``e``; at least 1 per experiment.
    """
    total = 0.0
    for r in residuals:
        m = len(r)
        if m < 3:
            total += max(m, 1)
            continue
        c = r - r.mean()
        den = float(np.dot(c, c))
        rho = float(np.dot(c[1:], c[:-1]) / den) if den > 0 else 0.0
        rho = min(max(rho, 0.0), _RHO_MAX)
        total += max(1.0, m * (1.0 - rho) / (1.0 + rho))
    return total


def information_criterion(mse: float, n_params: int, n_eff: float) -> float:
    """Gaussian BIC ``n_eff · ln(mse) + k · ln(n_eff)`` (dimensionless; lower is better).

    Parameters
    ----------
    mse : float
        Mean squared residual (bar²).
    n_params : int
        Free parameters of the structure.
    n_eff : float
        Effective sample size (see :func:`effective_sample_size`).
    """
    return n_eff * math.log(max(mse, 1e-30)) + n_params * math.log(n_eff)


@dataclass
class CandidateScore:
    """Training-set score of one candidate structure.

    Attributes
    ----------
    name : str
        Structure name (a key of :data:`STRUCTURES` or a user label).
    effects : list of str
        Effects / flexible laws on the base circuit.
    n_params : int
        Free parameters of its fit.
    rmse_bar : float
        Training RMSE of the period-mean pressure (bar), one value per dither period.
    bic : float
        Information criterion (lower is better; comparable within one selection).
    status : str
        Solver status of its fit.
    converged : bool
        Whether its fit converged (a non-converged fit is scored at its best iterate).
    wall_s : float
        Fit wall time (s).
    """

    name: str
    effects: list[str]
    n_params: int
    rmse_bar: float
    bic: float = float("nan")
    status: str = ""
    converged: bool = False
    wall_s: float = 0.0


@dataclass
class StructureSelection:
    """The chosen structure and every candidate's training-set score.

    Attributes
    ----------
    chosen : str
        Name of the structure with the lowest criterion.
    effects : list of str
        Its effects (what ``clutchlab evaluate --effects`` takes).
    criterion : str
        How the candidates were scored.
    n_periods : int
        Training residuals in the criterion (one per dither period).
    n_eff : float
        Effective sample size used for every candidate.
    candidates : list of CandidateScore
        Scores, in the order fitted.
    train : list of str
        Training experiments (the test ramp is never among them).
    wall_s : float
        Total wall time (s) of the selection.
    """

    chosen: str
    effects: list[str]
    criterion: str
    n_periods: int
    n_eff: float
    candidates: list[CandidateScore]
    train: list[str]
    wall_s: float
    results: dict[str, FitResult] = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        """JSON-ready summary (the fit results themselves are not included)."""
        return {
            "chosen": self.chosen,
            "effects": list(self.effects),
            "criterion": self.criterion,
            "n_periods": self.n_periods,
            "n_eff": self.n_eff,
            "train": list(self.train),
            "wall_s": self.wall_s,
            "candidates": [vars(c) for c in self.candidates],
        }

    def to_json(self, path=None) -> str:
        """The summary as JSON text; also written to ``path`` when given (atomically)."""
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            write_file_atomic(path, (text + "\n").encode("utf-8"), overwrite=True)
        return text

    def table(self) -> str:
        """Candidates with their training scores, as text (the chosen one marked)."""
        lines = [
            f"{'structure':10s} {'k':>3s} {'RMSE bar':>9s} {'BIC':>11s} {'fit s':>7s}  status",
        ]
        for c in self.candidates:
            mark = " *" if c.name == self.chosen else ""
            lines.append(
                f"{c.name:10s} {c.n_params:3d} {c.rmse_bar:9.4f} {c.bic:11.1f} "
                f"{c.wall_s:7.1f}  {c.status}{mark}"
            )
        lines.append(
            f"{self.criterion}; {self.n_periods} period means, n_eff = {self.n_eff:.0f}; "
            f"chosen: {self.chosen} ({', '.join(self.effects) or 'no flexible law'})"
        )
        return "\n".join(lines)

    def best_result(self) -> FitResult:
        """Fit result of the chosen structure."""
        return self.results[self.chosen]


class StructureSelector:
    """Fit each candidate structure on the training experiments and keep the best by BIC.

    scikit-learn contract: ``__init__`` stores its arguments, :meth:`fit` returns
    ``self`` with ``selection_`` (a :class:`StructureSelection`) and ``fitter_``
    (the fitted :class:`PhysicsFitter` of the chosen structure).

    Parameters
    ----------
    candidates : tuple of str or dict, optional
        Structure names (keys of :data:`STRUCTURES`), or a mapping ``label ->
        effects``; :data:`DEFAULT_CANDIDATES` by default.
    settings : FitSettings, optional
        Settings of every candidate's fit (training ramps, limits); ``free`` must be
        None (each structure frees its own laws' parameters).
    base_effects : tuple of str
        Library effects on in every candidate (declared effects of the user's model).
    """

    def __init__(
        self,
        candidates=None,
        settings: FitSettings | None = None,
        base_effects: tuple[str, ...] = (),
    ) -> None:
        self.candidates = candidates
        self.settings = settings
        self.base_effects = base_effects

    def _candidates(self) -> dict[str, tuple[str, ...]]:
        cands = self.candidates if self.candidates is not None else DEFAULT_CANDIDATES
        if isinstance(cands, dict):
            out = {str(k): tuple(v) for k, v in cands.items()}
        else:
            out = {name: structure_effects(name) for name in cands}
        if not out:
            raise FitError("no candidate structures to choose from")
        return {k: tuple(self.base_effects) + v for k, v in out.items()}

    def fit(self, data: Dataset | list[Trace]) -> StructureSelector:
        """Fit every candidate on the training experiments of ``data`` and choose.

        Raises
        ------
        FitError
            Bad settings, no training data, or no candidate that produced a model.
        """
        t0 = time.perf_counter()
        settings = self.settings or FitSettings()
        if settings.free is not None:
            raise FitError("structure selection frees each structure's own parameters: free=None")
        cands = self._candidates()
        if isinstance(data, Dataset):
            ramps = [r for r in settings.train_ramps if r in data.ramps]
            traces = list(data.select(ramps=ramps)) if ramps else []
        else:
            traces = list(data)
        if not traces:
            raise FitError(f"no training experiments (ramps {list(settings.train_ramps)})")
        scores: list[CandidateScore] = []
        residuals: dict[str, list[np.ndarray]] = {}
        results: dict[str, FitResult] = {}
        fitters: dict[str, PhysicsFitter] = {}
        plain_values: dict[str, float] | None = None
        plain_res: list[np.ndarray] = []
        plain_residuals = np.zeros(0)
        # Nested structures: the one without flexible laws first, so that every other
        # candidate starts at its optimum (a flexible law at its identity setting is
        # that model): a flexible fit can then only improve on it within its budget.
        order = sorted(cands, key=lambda k: bool(set(cands[k]) - set(self.base_effects)))
        for name in order:
            effects = cands[name]
            model = CircuitModel().with_effects(*effects)
            start = _warm_start(model, plain_values) if plain_values is not None else None
            fitter = PhysicsFitter(model, settings, start)
            t = time.perf_counter()
            try:
                fitter.fit(traces)
                result = fitter.result_
            except FitError as exc:
                result = getattr(exc, "result", None)
                if result is None:
                    raise
                fitter = PhysicsFitter.load(result.to_json())
            wall = time.perf_counter() - t
            params = result.params()
            res = [_period_residuals(tr, simulate(model, params, tr).pressure_bar) for tr in traces]
            allr = np.concatenate(res)
            if start is not None and _rms(allr) > _rms(plain_residuals):
                # The iterate is worse on the whole training set than its start (a pre-fit
                # on a subset can move away from what the other experiments need): the
                # start — the plain optimum with the laws at identity — is this
                # structure's best model, with the same residuals as the plain one.
                result = dataclasses.replace(
                    result,
                    values=dict(start.values),
                    status=f"{result.status}; kept its start (the iterate was worse)",
                    success=False,
                )
                fitter = PhysicsFitter.load(result.to_json())
                res, allr = plain_res, plain_residuals
            residuals[name] = res
            if not set(effects) - set(self.base_effects):
                plain_values = dict(result.values)
                plain_res, plain_residuals = res, allr
            results[name] = result
            fitters[name] = fitter
            scores.append(
                CandidateScore(
                    name=name,
                    effects=list(effects),
                    n_params=len(resolve_free(model, settings)),
                    rmse_bar=_rms(allr),
                    status=result.status,
                    converged=bool(result.success),
                    wall_s=wall,
                )
            )
        ref = min(scores, key=lambda c: c.rmse_bar).name
        n_eff = effective_sample_size(residuals[ref])
        for c in scores:
            c.bic = information_criterion(c.rmse_bar**2, c.n_params, n_eff)
        best = min(scores, key=lambda c: c.bic)
        self.selection_ = StructureSelection(
            chosen=best.name,
            effects=list(best.effects),
            criterion="BIC on training period-mean residuals, AR(1) effective sample size",
            n_periods=int(sum(len(r) for r in residuals[ref])),
            n_eff=float(n_eff),
            candidates=scores,
            train=[t.name for t in traces],
            wall_s=time.perf_counter() - t0,
            results=results,
        )
        self.fitter_ = fitters[best.name]
        return self


def select_structure(data, candidates=None, settings: FitSettings | None = None, **kw):
    """Shorthand: ``StructureSelector(candidates, settings, **kw).fit(data).selection_``."""
    return StructureSelector(candidates, settings, **kw).fit(data).selection_
