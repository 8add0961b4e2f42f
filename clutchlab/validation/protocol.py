"""The split protocol (DESIGN §5): fit on the training ramps, score on the unseen test ramp.

How the test experiments stay out of fitting and model selection:

- :class:`Protocol` hands out the **training** experiments only (:meth:`Protocol.train_traces`,
  :meth:`Protocol.fit`, :meth:`Protocol.selection_folds` — leave-one-experiment-out inside
  the training set for hyperparameters and effect choice). No method returns a test trace.
- :meth:`Protocol.score` takes a model that is **already fitted** (sklearn
  ``check_is_fitted``); it refuses a model that declares a test experiment among its
  training experiments (``train_experiments_`` or ``result_.train``, its own or those of a
  fitted model it holds, such as a hybrid's physics), and it passes the
  model input-only copies of the test experiments: their measured clutch pressure is
  replaced by NaN, so a model that reads it at predict time fails loudly instead of scoring
  well. The measured test pressure reaches the caller only inside the returned score.
"""

from __future__ import annotations

import math
import time
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from ..data import (
    CANONICAL_ORDER,
    Dataset,
    Trace,
    dither_period_mean,
    dither_period_samples,
    nominal_current,
    nominal_didt,
    ramp_rate_mA_s,
    ramps_fastest_first,
)
from ..errors import ClutchlabError, DataError
from .averaging import averaging_window, largest_dither_amp
from .hysteresis import branch_direction
from .metrics import (
    ACCURACY_KEYS,
    COVERAGE_REGIONS,
    SIGNAL_KINDS,
    compare_experiment,
    interval_coverage,
    pool_comparisons,
)
from .settings import AnalysisSettings
from .variants import supports_std

__all__ = [
    "EvaluationError",
    "ExperimentReference",
    "LeakageError",
    "Prediction",
    "Protocol",
    "VariantScore",
    "inputs_only",
    "is_fitted",
]


class LeakageError(ClutchlabError, RuntimeError):
    """A model that has seen a test experiment was handed to the protocol for scoring."""


class EvaluationError(ClutchlabError, RuntimeError):
    """A model's prediction cannot be scored (wrong length, non-finite values)."""


def inputs_only(trace: Trace) -> Trace:
    """Copy of ``trace`` whose measured clutch pressure is NaN (the target hidden).

    Parameters
    ----------
    trace : Trace
        A test experiment.

    Returns
    -------
    Trace
        Same inputs (time, currents, dither, line / prime pressure, temperature) and
        metadata; ``clutch_pressure_bar`` all NaN.
    """
    return trace.with_signals(clutch_pressure_bar=np.full(len(trace), np.nan))


@dataclass(frozen=True)
class ExperimentReference:
    """The measured side of one test experiment, as the metrics and figures need it.

    Attributes
    ----------
    name, ramp : str
        Experiment name and ramp label.
    time_s : numpy.ndarray
        Sample time, s.
    current_mA : numpy.ndarray
        Nominal current, mA.
    direction : numpy.ndarray
        Branch per sample (1 rising, -1 falling, 0 hold).
    line_bar : numpy.ndarray
        Measured line pressure, bar.
    period_samples : float
        Samples per dither period.
    measured_bar : numpy.ndarray
        Measured clutch pressure, raw, bar.
    sample_rate_Hz : float
        Sample rate of the log, Hz (NaN when not given).
    dither_amp_max_mA : float or None
        Largest logged dither amplitude, mA (None when the log has no ``dither_amp_mA``).
    """

    name: str
    ramp: str | None
    time_s: np.ndarray
    current_mA: np.ndarray
    direction: np.ndarray
    line_bar: np.ndarray
    period_samples: float
    measured_bar: np.ndarray
    sample_rate_Hz: float = float("nan")
    dither_amp_max_mA: float | None = None

    @property
    def averaging(self) -> dict[str, Any]:
        """The window of :meth:`period_mean` (:func:`~.averaging.averaging_window`): samples,
        ms, the dither frequency it is the period of, and whether there is a dither."""
        return averaging_window(self.period_samples, self.sample_rate_Hz, self.dither_amp_max_mA)

    @cached_property
    def measured_mean_bar(self) -> np.ndarray:
        """Measured clutch pressure averaged over one dither period, bar."""
        return self.period_mean(self.measured_bar)

    def period_mean(self, x: np.ndarray) -> np.ndarray:
        """``x`` averaged over one dither period of this experiment (same unit)."""
        return dither_period_mean(x, self.period_samples)

    def signal(self, kind: str, x: np.ndarray) -> np.ndarray:
        """``x`` as signal ``kind``: ``"period_mean"`` or ``"raw"``."""
        return self.period_mean(x) if kind == "period_mean" else np.asarray(x, dtype=float)

    @classmethod
    def of(cls, trace: Trace, settings: AnalysisSettings) -> ExperimentReference:
        """Reference of ``trace`` (its nominal current, branches, line pressure)."""
        return cls(
            name=trace.name,
            ramp=trace.ramp,
            time_s=np.asarray(trace.time_s, dtype=float),
            current_mA=nominal_current(trace),
            direction=branch_direction(nominal_didt(trace), settings),
            line_bar=np.asarray(trace.get("line_pressure_bar"), dtype=float),
            period_samples=dither_period_samples(trace),
            measured_bar=np.asarray(trace.get("clutch_pressure_bar"), dtype=float),
            sample_rate_Hz=float(trace.sample_rate_Hz),
            dither_amp_max_mA=largest_dither_amp(trace),
        )


@dataclass(frozen=True)
class Prediction:
    """A model's prediction of one experiment.

    Attributes
    ----------
    mean_bar : numpy.ndarray
        Predicted clutch pressure per sample, bar.
    std_bar : numpy.ndarray or None
        Predictive standard deviation, bar, when the model gives one.
    """

    mean_bar: np.ndarray
    std_bar: np.ndarray | None = None


@dataclass
class VariantScore:
    """Scores of one fitted variant on the test experiments.

    Attributes
    ----------
    name : str
        Variant name.
    metrics : dict
        :data:`~clutchlab.validation.metrics.METRIC_KEYS` on the dither-period mean
        (primary): bar, %, mA, s.
    raw : dict
        :data:`~clutchlab.validation.metrics.ACCURACY_KEYS` on the raw pressure (secondary).
    details : dict
        Diagnostics per signal kind (bins counted, latch biases, censored latches) and, for
        a model with a latch classifier (``predict_latch``), ``classifier_accuracy`` on the
        test experiments (fraction).
    per_experiment : dict
        ``experiment → signal kind → per-experiment numbers``.
    predictions : dict
        ``experiment → Prediction`` (raw model output, bar; the standard deviation where
        requested and offered).
    reference : dict
        ``experiment → ExperimentReference`` (the measured side).
    """

    name: str
    metrics: dict[str, float]
    raw: dict[str, float]
    details: dict[str, Any] = field(default_factory=dict)
    per_experiment: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    predictions: dict[str, Prediction] = field(default_factory=dict)
    reference: dict[str, ExperimentReference] = field(default_factory=dict)


def is_fitted(model: Any) -> bool:
    """Whether ``model`` is fitted, by the scikit-learn convention.

    ``model.__sklearn_is_fitted__()`` when defined, else whether it has a learned attribute
    (a public name ending in ``_``), as :func:`sklearn.utils.validation.check_is_fitted`
    decides without requiring a scikit-learn base class.
    """
    if not callable(getattr(model, "fit", None)):
        raise TypeError(f"{type(model).__name__} has no fit method: not a model")
    check = getattr(model, "__sklearn_is_fitted__", None)
    if callable(check):
        return bool(check())
    return any(k.endswith("_") and not k.startswith("__") for k in vars(model))


#: Factor by which a test experiment's ramp rate may lie outside the training experiments'
#: before the report calls it an extrapolation (10 %: a rate "between" the trained ones
#: that only rounding puts outside is not one).
RATE_EXTRAPOLATION = 1.1

#: How deep :func:`_declared_training` looks into models held by a model.
_PART_DEPTH = 4


def _declared_training(
    model: Any, depth: int = 0, seen: set[int] | None = None
) -> list[str] | None:
    """Every experiment ``model`` declares it was fitted on, or None if it declares none.

    Its own ``train_experiments_`` (else ``result_.train``), and those of the fitted models
    it holds (learned attributes ending in ``_`` that predict: a hybrid's ``physics_`` and
    ``residual_``, a wrapper's ``fitter_``), so a composite model whose part saw a test
    experiment is refused even when the composite lists only its own traces.
    """
    seen = set() if seen is None else seen
    if id(model) in seen:
        return None
    seen.add(id(model))
    names = getattr(model, "train_experiments_", None)
    if names is None:
        result = getattr(model, "result_", None)
        names = getattr(result, "train", None)
    found = None if names is None or isinstance(names, str) else [str(n) for n in names]
    if depth >= _PART_DEPTH:
        return found
    for key, part in list(getattr(model, "__dict__", {}).items()):
        if not key.endswith("_") or key.startswith("_") or part is None:
            continue
        if isinstance(part, str | bytes | int | float | np.ndarray | list | tuple | dict):
            continue
        if not callable(getattr(part, "predict", None)):
            continue
        inner = _declared_training(part, depth + 1, seen)
        if inner is not None:
            found = (found or []) + inner
    return found


class Protocol:
    """Train / test split of a dataset by ramp label, and scoring of fitted models.

    Parameters
    ----------
    dataset : Dataset
        The experiments (DESIGN §3 data contract).
    train : sequence of str
        Ramp labels fitted on (default fast, slow).
    test : sequence of str
        Ramp labels scored on (default medium); disjoint from ``train``.
    settings : AnalysisSettings, optional
        Hysteresis bins and latch margin of the metrics.

    Raises
    ------
    DataError
        If a label is unknown, the two sets overlap, or either selects no experiment.

    Examples
    --------
    >>> protocol = Protocol(dataset, train=("fast", "slow"), test=("medium",))
    >>> model, fit_s = protocol.fit(FittedPhysics())        # training experiments only
    >>> score = protocol.score("physics_fitted", model, fit_s=fit_s)
    >>> score.metrics["rmse_bar"]
    """

    def __init__(
        self,
        dataset: Dataset,
        train: Sequence[str] = ("fast", "slow"),
        test: Sequence[str] = ("medium",),
        settings: AnalysisSettings | None = None,
    ) -> None:
        train, test = tuple(train), tuple(test)
        problems = []
        if not train or not test:
            problems.append("both the training and the test ramp labels must be given")
        overlap = sorted(set(train) & set(test))
        if overlap:
            problems.append(f"ramp label(s) {overlap} are both training and test")
        unknown = sorted(set(train + test) - set(dataset.ramps))
        if unknown:
            problems.append(f"unknown ramp label(s) {unknown}; the dataset has {dataset.ramps}")
        if problems:
            raise DataError("invalid train / test split", problems)
        self.train_ramps = train
        self.test_ramps = test
        self.settings = settings or AnalysisSettings()
        self._train = tuple(dataset.select(ramps=train))
        self._test = tuple(dataset.select(ramps=test))
        self._references: dict[str, ExperimentReference] | None = None
        self.dataset_summary = _summary(dataset)

    # -- what fitting may see -------------------------------------------------------------

    @property
    def train_names(self) -> list[str]:
        """Names of the training experiments."""
        return [t.name for t in self._train]

    @property
    def test_names(self) -> list[str]:
        """Names of the test experiments (names only)."""
        return [t.name for t in self._test]

    def train_traces(self) -> tuple[Trace, ...]:
        """The training experiments (the only experiments a model may be fitted on)."""
        return self._train

    @cached_property
    def ramp_rates(self) -> dict[str, Any]:
        """Ramp rates of the split (mA/s) and the test experiments outside the training ones.

        A test experiment is *extrapolated* when its ramp rate lies outside the training
        experiments' by more than :data:`RATE_EXTRAPOLATION` (a factor): the rate-dependent
        part of every model (the band's widening, the latch delays) is then an extrapolation,
        and the ML variants' predictive std was never calibrated there. Reading the rates
        does not fit anything on the test experiments.

        Returns
        -------
        dict
            ``train`` [lowest, highest] mA/s (None without a rate), ``test`` name → mA/s,
            ``extrapolated`` the test names outside ``train`` widened by the factor.
        """
        train = [r for r in (ramp_rate_mA_s(t) for t in self._train) if r]
        test = {t.name: ramp_rate_mA_s(t) for t in self._test}
        if not train:
            return {"train": None, "test": test, "extrapolated": []}
        lo, hi = min(train), max(train)
        out = [
            n
            for n, r in test.items()
            if r and not lo / RATE_EXTRAPOLATION <= r <= hi * RATE_EXTRAPOLATION
        ]
        return {"train": [lo, hi], "test": test, "extrapolated": out}

    def selection_folds(self) -> Iterator[tuple[tuple[Trace, ...], Trace]]:
        """Leave-one-experiment-out folds inside the training set, for model selection.

        Yields
        ------
        fit_traces : tuple of Trace
            Every training experiment but one.
        held_out : Trace
            The one left out.
        """
        for k, held in enumerate(self._train):
            yield self._train[:k] + self._train[k + 1 :], held

    def fit(self, model: Any) -> tuple[Any, float]:
        """Fit ``model`` on the training experiments.

        Parameters
        ----------
        model : object
            Unfitted model with ``fit(traces)``.

        Returns
        -------
        model : object
            The fitted model.
        fit_s : float
            Wall time of ``fit``, s.
        """
        t0 = time.perf_counter()
        model.fit(list(self._train))
        return model, time.perf_counter() - t0

    # -- scoring --------------------------------------------------------------------------

    def _refs(self) -> dict[str, ExperimentReference]:
        if self._references is None:
            self._references = {
                t.name: ExperimentReference.of(t, self.settings) for t in self._test
            }
        return self._references

    def _check_model(self, name: str, model: Any) -> None:
        if not is_fitted(model):
            from sklearn.exceptions import NotFittedError

            raise NotFittedError(
                f"variant {name!r}: the model is not fitted; the protocol scores fitted "
                "models only (fit it with Protocol.fit, on the training experiments)"
            )
        seen = _declared_training(model)
        if seen is not None:
            leaked = sorted(set(seen) & set(self.test_names))
            if leaked:
                raise LeakageError(
                    f"variant {name!r} was fitted on test experiment(s) {leaked}; "
                    f"fit it on the training experiments only (ramps {list(self.train_ramps)})"
                )

    @staticmethod
    def _checked(name: str, trace: Trace, what: str, arr: Any) -> np.ndarray:
        arr = np.asarray(arr, dtype=float)
        problem = None
        if arr.shape != (len(trace),):
            problem = f"{what} has shape {arr.shape}, expected ({len(trace)},)"
        elif not np.isfinite(arr).all():
            problem = (
                f"{what} has {int((~np.isfinite(arr)).sum())} non-finite value(s) (a model "
                "that reads the measured clutch pressure at predict time sees NaN there)"
            )
        if problem:
            raise EvaluationError(f"variant {name!r} on test experiment {trace.name!r}: {problem}")
        return arr

    def _latch_accuracy(self, model: Any) -> float:
        """Share of test samples whose latch state the model's classifier gets right.

        Truth: the latch labels of the measured pressure
        (:func:`clutchlab.residual_ml.labels.latch_labels`), latch-event samples left out;
        prediction: ``model.predict_latch`` on the input-only test experiment.
        """
        from ..residual_ml.labels import latch_labels

        hits = total = 0
        for trace in self._test:
            truth = np.asarray(latch_labels(trace))
            pred = np.asarray(model.predict_latch(inputs_only(trace)))
            keep = truth >= 0
            hits += int(np.sum(pred[keep] == truth[keep]))
            total += int(keep.sum())
        return hits / total if total else float("nan")

    def _coverage(self, refs, predictions) -> dict[str, float]:
        """Pooled ±2σ coverage per region of the period-mean error (empty without a std)."""
        counts = {r: [0, 0] for r in COVERAGE_REGIONS}
        for n, ref in refs.items():
            pred = predictions[n]
            if pred.std_bar is None:
                continue
            got = interval_coverage(
                ref.time_s,
                ref.period_mean(ref.line_bar),
                ref.measured_mean_bar,
                ref.period_mean(pred.mean_bar),
                ref.period_mean(pred.std_bar),
                self.settings,
            )
            for r, (inside, total) in got.items():
                counts[r][0] += inside
                counts[r][1] += total
        if not any(total for _, total in counts.values()):
            return {}
        return {r: (i / t if t else float("nan")) for r, (i, t) in counts.items()}

    @property
    def featured(self) -> str:
        """The test experiment drawn in single-experiment figures (the middle one by name)."""
        names = sorted(self.test_names)
        return names[len(names) // 2]

    def score(
        self,
        name: str,
        model: Any,
        fit_s: float = 0.0,
        std_for: Collection[str] | None = None,
    ) -> VariantScore:
        """Score a fitted model on the test experiments.

        Parameters
        ----------
        name : str
            Variant name for the report.
        model : object
            Fitted model with ``predict(trace)`` (optionally ``return_std``).
        fit_s : float
            Its fit wall time, s (recorded as ``fit_s``).
        std_for : collection of str, optional
            Test experiments on which to also get the predictive standard deviation (a
            separate, untimed ``predict(trace, return_std=True)``; ``predict_s`` times the
            mean alone); all of them by default.

        Returns
        -------
        VariantScore

        Raises
        ------
        sklearn.exceptions.NotFittedError
            If the model is not fitted.
        LeakageError
            If the model declares a test experiment among its training experiments.
        EvaluationError
            If a prediction has the wrong length or non-finite values.
        """
        self._check_model(name, model)
        refs = self._refs()
        with_std = supports_std(model)
        predictions: dict[str, Prediction] = {}
        predict_s = 0.0
        for trace in self._test:
            hidden = inputs_only(trace)
            t0 = time.perf_counter()
            mean = model.predict(hidden)
            predict_s += time.perf_counter() - t0
            mean = self._checked(name, trace, "prediction", mean)
            std = None
            if with_std and (std_for is None or trace.name in std_for):
                std = self._checked(
                    name, trace, "standard deviation", model.predict(hidden, return_std=True)[1]
                )
            predictions[trace.name] = Prediction(mean, std)
        pooled, per_exp = {}, {n: {} for n in refs}
        for kind in SIGNAL_KINDS:
            comps = []
            for n, ref in refs.items():
                c = compare_experiment(
                    n,
                    ref.current_mA,
                    ref.direction,
                    ref.line_bar,
                    ref.signal(kind, ref.measured_bar),
                    ref.signal(kind, predictions[n].mean_bar),
                    self.settings,
                    ref.time_s,
                )
                comps.append(c)
                per_exp[n][kind] = c.summary()
            pooled[kind] = pool_comparisons(comps)
        metrics = {k: pooled["period_mean"][k] for k in ACCURACY_KEYS}
        metrics |= {"fit_s": float(fit_s), "predict_s": predict_s}
        details: dict[str, Any] = {
            kind: {k: v for k, v in pooled[kind].items() if k not in ACCURACY_KEYS}
            for kind in SIGNAL_KINDS
        }
        coverage = self._coverage(refs, predictions)
        if coverage:
            details["coverage_2sigma"] = coverage
            details["coverage_experiments"] = sorted(
                n for n, pr in predictions.items() if pr.std_bar is not None
            )
        if callable(getattr(model, "predict_latch", None)):
            details["classifier_accuracy"] = self._latch_accuracy(model)
        from ..residual_ml import latch_decision_text

        if said := latch_decision_text(model):  # None for a model without a latch decision
            details["latch_decision"] = said
        if callable(getattr(model, "gp_hyperparameters", None)):
            details["gp_hyperparameters"] = model.gp_hyperparameters()
            details["gp_at_bounds"] = model.hyperparameters_at_bounds()
        if getattr(model, "form_", None) is not None:  # a hybrid's residual form, and why
            details["residual_form"] = model.form_
            details["residual_form_loeo_rmse_bar"] = dict(getattr(model, "form_scores_", {}))
            kappa = float(getattr(model, "standalone_handicap_", math.nan))
            if math.isfinite(kappa):  # the handicap the auto choice used
                details["residual_form_standalone_handicap"] = kappa
        return VariantScore(
            name=name,
            metrics=metrics,
            raw={k: pooled["raw"][k] for k in ACCURACY_KEYS},
            details=details,
            per_experiment=per_exp,
            predictions=predictions,
            reference=refs,
        )


def _summary(dataset: Dataset) -> dict[str, Any]:
    """Dataset summary for the report: size, ramps, durations, rates, signals, metadata."""
    # fastest first: a user's labels ("r5s", "r20s", …) say nothing in alphabetical order
    ramps = {label: len(exps) for label, exps in ramps_fastest_first(dataset).items()}
    present = {s for t in dataset for s in t.signals}
    signals = [s for s in CANONICAL_ORDER if s in present]
    return {
        "root": str(dataset.root) if dataset.root is not None else None,
        # the channel map(s) the logs were read through (a manifest's or --map): how the
        # measured signals came about, for the report's reader to repeat it
        "channel_maps": dataset.channel_maps,
        "experiments": len(dataset),
        "ramps": ramps,
        "samples": int(sum(len(t) for t in dataset)),
        "duration_s": float(sum(t.duration_s for t in dataset)),
        "sample_rate_Hz": sorted({round(t.sample_rate_Hz, 6) for t in dataset}),
        "signals": signals,
        # what reading each log noticed (e.g. no dither amplitude: the physics is driven
        # without dither), as `clutchlab data check` and the terminal say it: in the report
        # too, for its reader, who did not see the terminal
        "notes": {
            name: list(report.notes) for name, report in dataset.reports.items() if report.notes
        },
        "table": [
            {
                "name": t.name,
                "ramp": t.ramp,
                "samples": len(t),
                "duration_s": t.duration_s,
                **{k: v for k, v in t.meta.items() if k not in ("ramp", "file")},
            }
            for t in dataset
        ],
    }
