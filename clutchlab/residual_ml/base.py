"""Common machinery of the trace-level estimators: inputs, feature blocks, the sklearn contract.

Every estimator of :mod:`clutchlab.residual_ml` accepts two kinds of input:

- **traces** — a :class:`~clutchlab.data.Trace`, a :class:`~clutchlab.data.Dataset` or a
  sequence of traces. ``fit(traces)`` builds the features, the target (dither-period-mean
  clutch pressure, bar) and the latch labels itself; ``predict(trace)`` returns one clutch
  pressure per sample (bar), evaluated at knots along the trace and interpolated
  (:mod:`~clutchlab.residual_ml.paths`); ``predict(dataset)`` returns a list of such arrays.
- **arrays** — ``fit(X, y)`` / ``predict(X)`` with ``X`` the n × d matrix of feature columns
  (in the order of ``feature_names_`` when trained on traces) and ``y`` the clutch pressure
  (bar), every row predicted exactly. This is the plain scikit-learn interface used by
  ``check_estimator``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import NotFittedError
from sklearn.utils.validation import validate_data

from ..data import LINE_PRESSURE_BAR, Trace, as_traces, dither_period_samples
from ..errors import DataError
from ._threads import single_thread
from .features import FEATURES, FeatureBuilder, target_pressure
from .labels import LatchLabelRule, latch_labels

#: A GP length scale in a hyperparameter-at-bound entry, by input index.
_LENGTH_SCALE = re.compile(r"^length_scale\[(\d+)\]")

__all__ = [
    "FIT_SIGNALS",
    "PREDICT_SIGNALS",
    "Block",
    "TraceEstimator",
    "as_traces",
    "check_finite_signals",
]

#: Signals a fit reads from a training trace, when the trace holds them: the target (clutch
#: pressure, bar), the line pressure of the latch labels and the latched plateau's
#: reference (bar), and the inputs of the features (time s, currents and dither mA / Hz).
FIT_SIGNALS: tuple[str, ...] = (
    "time_s",
    "current_cmd_mA",
    "current_mA",
    "dither_amp_mA",
    "dither_freq_Hz",
    "line_pressure_bar",
    "clutch_pressure_bar",
)
#: Signals a prediction reads from a trace, when the trace holds them: the fit's, less the
#: target (the clutch pressure is only compared with, never read).
PREDICT_SIGNALS: tuple[str, ...] = tuple(s for s in FIT_SIGNALS if s != "clutch_pressure_bar")


def check_finite_signals(
    traces: Sequence[Trace], signals: Sequence[str] = FIT_SIGNALS, role: str = "training"
) -> None:
    """Refuse traces with a non-finite value in one of ``signals`` (those they hold).

    ``role`` names the experiments in the error (``"training"``, ``"predicted"``).

    Raises
    ------
    DataError
        Listing every experiment and signal with a NaN or infinite value: the count, the
        first row (1-based, as in the logged file) and its time (s).
    """
    problems = []
    for t in traces:
        time_s = np.asarray(t.time_s, dtype=float)
        for name in signals:
            if not t.has(name):
                continue
            bad = ~np.isfinite(np.asarray(t.get(name), dtype=float))
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                at = f" (t = {time_s[i]:.6g} s)" if np.isfinite(time_s[i]) else ""
                problems.append(
                    f"experiment {t.name!r}: {name} has {int(bad.sum())} non-finite value(s), "
                    f"the first at row {i + 1}{at}"
                )
    if problems:
        raise DataError(f"non-finite values in the {role} experiments", problems)


def _numeric_lag(value) -> float:
    """A ``lag_s`` parameter as seconds (``"auto"`` before fitting: 0); ModelError if invalid."""
    from ..errors import ModelError

    if isinstance(value, str):
        if value == "auto":
            return 0.0
        raise ModelError(f"lag_s must be 'auto' or a time constant >= 0 s, got {value!r}")
    try:
        lag = float(value)
    except (TypeError, ValueError):
        lag = float("nan")
    if not (np.isfinite(lag) and lag >= 0):
        raise ModelError(f"lag_s must be 'auto' or a time constant >= 0 s, got {value!r}")
    return lag


@dataclass
class Block:
    """Features, target, weights and labels of one experiment (or one array input).

    Attributes
    ----------
    name : str
        Experiment name.
    X : numpy.ndarray
        n × d features (units of the feature builder).
    y : numpy.ndarray
        n targets (bar).
    weight : numpy.ndarray
        n effective-observation weights (1 / samples per dither period for traces, whose
        period-mean target is correlated over one period).
    labels : numpy.ndarray
        n latch labels (1 latched, 0 unlatched, −1 latch event).
    state : numpy.ndarray
        n latched (1) / unlatched (0) Schmitt-trigger state, events included.
    ref : numpy.ndarray or None
        n reference pressures (bar) the latched regime's target is taken relative to
        (line pressure), or None.
    """

    name: str
    X: np.ndarray
    y: np.ndarray
    weight: np.ndarray
    labels: np.ndarray
    state: np.ndarray
    ref: np.ndarray | None = None


class TraceEstimator(RegressorMixin, BaseEstimator):
    """Base of the trace-level regressors (not used directly).

    Subclasses define ``_default_features``, ``_fit_blocks(blocks)`` and
    ``_predict_matrix(X, path, return_std)``.
    """

    _default_features: tuple[str, ...] = ()

    # -- features ----------------------------------------------------------------------------

    def _builder(self, lag_s: float | None = None) -> FeatureBuilder:
        feats = getattr(self, "features", None)
        if lag_s is None:
            lag_s = getattr(self, "lag_s_", None)
        if lag_s is None:
            lag_s = _numeric_lag(getattr(self, "lag_s", 0.0))
        return FeatureBuilder(
            tuple(feats) if feats else self._default_features,
            float(getattr(self, "didt_periods", 5.0)),
            lag_s=float(lag_s),
        )

    def _resolve_lag(self, traces: list[Trace]) -> float:
        """Time constant of ``current_lag_mA`` (s): the ``lag_s`` parameter, or chosen by
        leave-one-ramp-rate-out on ``traces`` (:func:`~.lag.select_lag`) when ``"auto"``."""
        from .lag import select_lag

        self.lag_selection_ = None
        param = getattr(self, "lag_s", 0.0)
        builder = self._builder(0.0)
        if "current_lag_mA" not in builder.features:
            return _numeric_lag(param)
        if isinstance(param, str) and param == "auto":
            self.lag_selection_ = select_lag(traces, builder)
            return self.lag_selection_.lag_s
        return _numeric_lag(param)

    def _rule(self) -> LatchLabelRule:
        rule = getattr(self, "label_rule", None)
        return rule if rule is not None else LatchLabelRule()

    def _block(self, trace: Trace, physics: dict[str, np.ndarray] | None = None) -> Block:
        X = self._builder().build(trace, physics)
        y = target_pressure(trace, getattr(self, "target", "period_mean"))
        w = np.full(len(trace), 1.0 / dither_period_samples(trace))
        labels, state = latch_labels(trace, self._rule(), return_state=True)
        return Block(trace.name, X, y, w, labels, state)

    def _array_block(self, X: np.ndarray, y: np.ndarray) -> Block:
        """Block of array input: threshold labels (line pressure 17.7 bar, no events)."""
        rule = self._rule()
        lab = (LINE_PRESSURE_BAR - y <= rule.margin_bar).astype(np.int8)
        return Block("arrays", X, y, np.ones(y.size), lab, lab.copy())

    # -- sklearn contract --------------------------------------------------------------------

    def fit(self, X, y=None):
        """Fit on traces (``y`` None) or on a feature matrix and targets.

        Parameters
        ----------
        X : Trace, Dataset, sequence of Trace, or array_like
            Training experiments, or an n × d feature matrix (feature units).
        y : array_like, optional
            n clutch pressures (bar); only with a feature matrix.

        Returns
        -------
        self
            The fitted estimator.

        Raises
        ------
        DataError
            If there are no training experiments, a trace lacks a needed signal or has a
            non-finite value in one it is fitted on (experiment, signal and row named), or
            ``y`` is given with traces.
        """
        traces = as_traces(X, "training")
        if traces is not None:
            if y is not None:
                raise DataError("y must be None when fitting on traces (targets come from them)")
            check_finite_signals(traces)
            self.lag_s_ = self._resolve_lag(traces)
            self.feature_names_ = list(self._builder().names)
            blocks = self._trace_blocks(traces)
            self.n_features_in_ = len(self.feature_names_)
            self.train_experiments_ = [t.name for t in traces]
        else:
            Xa, ya = validate_data(self, X, y, y_numeric=True, dtype=np.float64)
            self.lag_s_ = _numeric_lag(getattr(self, "lag_s", 0.0))
            self.feature_names_ = [f"x{j}" for j in range(Xa.shape[1])]
            blocks = [self._array_block(Xa, ya)]
            self.train_experiments_ = []
        self._fit_blocks(blocks)
        return self

    def _trace_blocks(self, traces: list[Trace]) -> list[Block]:
        return [self._block(t) for t in traces]

    def _check_fitted(self) -> None:
        if not hasattr(self, "feature_names_"):
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet; call fit(traces) first"
            )

    def _trace_matrix(self, trace: Trace) -> np.ndarray:
        return self._builder().build(trace)

    def predict(self, X, return_std: bool = False):
        """Clutch pressure (bar) per sample.

        Parameters
        ----------
        X : Trace, Dataset, sequence of Trace, or array_like
            One trace (→ one array), several (→ a list of arrays), or an n × d feature matrix.
        return_std : bool
            Also return the predictive standard deviation (bar) of a measured
            dither-period mean: the GP's latent std and its observation noise.

        Returns
        -------
        mean : numpy.ndarray or list of numpy.ndarray
            Predicted clutch pressure, bar.
        std : numpy.ndarray or list of numpy.ndarray
            Predictive standard deviation, bar; only if ``return_std``.

        Raises
        ------
        NotFittedError
            If the estimator is not fitted.
        DataError
            If a trace has a non-finite value in a signal a prediction reads
            (:data:`PREDICT_SIGNALS`; experiment, signal and row named).
        """
        self._check_fitted()
        traces = as_traces(X)
        if traces is not None:
            check_finite_signals(traces, PREDICT_SIGNALS, role="predicted")
        with single_thread("blas"):
            if traces is None:
                Xa = validate_data(self, X, reset=False, dtype=np.float64)
                return self._predict_matrix(Xa, path=False, return_std=return_std)
            outs = [self._predict_trace(t, return_std) for t in traces]
        if isinstance(X, Trace):
            return outs[0]
        if return_std:
            return [o[0] for o in outs], [o[1] for o in outs]
        return outs

    def _predict_trace(self, trace: Trace, return_std: bool):
        return self._predict_matrix(self._trace_matrix(trace), path=True, return_std=return_std)

    def score(self, X, y=None, sample_weight=None) -> float:
        """R² of the prediction: on traces against the dither-period-mean pressure."""
        from sklearn.metrics import r2_score

        traces = as_traces(X)
        if traces is None:
            return super().score(X, y, sample_weight=sample_weight)
        pred = self.predict(traces)
        y_true = np.concatenate([target_pressure(t) for t in traces])
        return float(r2_score(y_true, np.concatenate(pred)))

    # -- persistence -------------------------------------------------------------------------

    def save(self, path) -> None:
        """Write the fitted model as JSON (``path``) + NPZ (same name, ``.npz``); no pickle.

        See :func:`~clutchlab.residual_ml.persist.save_model` (a ``.npz`` path, or a file
        clutchlab did not write standing at either name, is refused before writing).
        """
        from .persist import save_model

        save_model(self, path)

    @classmethod
    def load(cls, path):
        """Read a model written by :meth:`save`.

        Raises
        ------
        ModelError
            If the file holds another kind of model or is not a clutchlab model.
        """
        from ..errors import ModelError
        from .persist import load_model

        model = load_model(path)
        if not isinstance(model, cls):
            raise ModelError(f"{path} holds a {type(model).__name__}, not a {cls.__name__}")
        return model

    def gp_hyperparameters(self) -> dict[str, dict]:
        """Fitted hyperparameters of every GP of the model, by part, JSON-ready.

        Parts: ``gp`` (one GP) and its ``variance_floor`` (the GP of its log squared
        held-out residual, when fitted), ``unlatched`` / ``latched`` (one per latch state),
        a hybrid's prefixed ``residual.``. Each entry is
        :meth:`~clutchlab.residual_ml.local_gp.LocalGPRegressor.hyperparameters`, with
        ``at_bounds`` listing those that ended on a bound of their range.
        """
        self._check_fitted()
        inner = getattr(self, "residual_", None)
        if inner is not None:
            return {f"residual.{k}": v for k, v in inner.gp_hyperparameters().items()}
        if hasattr(self, "gps_"):
            names = {0: "unlatched", 1: "latched"}
            return {names[g]: gp.hyperparameters() for g, gp in sorted(self.gps_.items())}
        parts = {"gp": getattr(self, "gp_", None)}
        parts["variance_floor"] = getattr(self, "variance_floor_", None)
        return {k: gp.hyperparameters() for k, gp in parts.items() if gp is not None}

    def hyperparameters_at_bounds(self) -> list[str]:
        """``"part: name (side bound value)"`` for every GP hyperparameter on a bound; a
        length scale also names its input feature (``length_scale[4] = didt_mA_s``)."""
        inner = getattr(self, "residual_", None)
        if inner is not None:
            return [f"residual.{entry}" for entry in inner.hyperparameters_at_bounds()]
        names = list(getattr(self, "feature_names_", None) or [])

        def named(entry: str) -> str:
            entry = entry.replace("target units²", "bar²")  # the GPs here model pressures
            match = _LENGTH_SCALE.match(entry)
            if match is None or int(match[1]) >= len(names):
                return entry
            name = names[int(match[1])]
            unit = FEATURES.get(name, ("", ""))[0]
            rest = entry[match.end() :]
            if unit:
                rest = rest.replace("in input units", unit if unit != "1" else "(unitless)")
            if "(upper bound" in rest:  # the likelihood wanted the feature to matter less
                rest += (
                    ": the prediction hardly changes along this feature (expected when it "
                    "varies little in the training data, e.g. one dither amplitude)"
                )
            return f"{match[0]} = {name}{rest}"

        return [
            f"{part}: {named(entry)}"
            for part, h in self.gp_hyperparameters().items()
            for entry in h.get("at_bounds", [])
        ]

    # -- helpers for subclasses --------------------------------------------------------------

    @staticmethod
    def _stack(blocks: list[Block]) -> Block:
        if len(blocks) == 1:
            return blocks[0]
        refs = [b.ref for b in blocks]
        return Block(
            "+".join(b.name for b in blocks),
            np.concatenate([b.X for b in blocks]),
            np.concatenate([b.y for b in blocks]),
            np.concatenate([b.weight for b in blocks]),
            np.concatenate([b.labels for b in blocks]),
            np.concatenate([b.state for b in blocks]),
            None if any(r is None for r in refs) else np.concatenate(refs),
        )
