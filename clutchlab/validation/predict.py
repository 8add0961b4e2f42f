"""Apply a saved model to a dataset: per-sample predictions and their scores.

What ``clutchlab predict`` runs: a model trained or fitted earlier (``clutchlab train``,
``fit-physics``, a design's parameter file) on the logs of another day, stand or unit,
without fitting anything again.
"""

from __future__ import annotations

import time
import zipfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data import (
    Trace,
    dither_period_mean,
    dither_period_samples,
    model_doc_kind,
    nominal_current,
    pressure_metrics,
    read_json_object,
)
from ..errors import ClutchlabError, ModelError
from .averaging import averaging_window, largest_dither_amp
from .variants import supports_std

__all__ = [
    "ExperimentPrediction",
    "LoadedModel",
    "load_predictor",
    "overall_metrics",
    "predict_traces",
    "prediction_table",
]


@dataclass(frozen=True)
class LoadedModel:
    """A saved model, ready to predict.

    Attributes
    ----------
    model : object
        Has ``predict(trace)`` → clutch pressure per sample (bar); with ``has_std`` also
        ``predict(trace, return_std=True)`` → (mean, std) (bar).
    kind : str
        What the file held, in words (e.g. ``"paper_svc_gp model (clutchlab train)"``).
    train_experiments : tuple of str
        Experiments the model was trained or fitted on (empty when not known or none).
    """

    model: object
    kind: str
    train_experiments: tuple[str, ...]

    @property
    def has_std(self) -> bool:
        """Whether the model gives a predictive standard deviation (``return_std``)."""
        return supports_std(self.model)

    def check_std(self, what: str = "") -> None:
        """Refuse a predictive std the model does not give.

        Raises
        ------
        ModelError
            Naming the model (and ``what`` asked for it, e.g. ``"--std: "``).
        """
        if not self.has_std:
            raise ModelError(f"{what}the {self.kind} has no predictive std (standard deviation)")


def load_predictor(path: str | Path, substeps: int | None = None) -> LoadedModel:
    """Read any model clutchlab saves, for prediction.

    Parameters
    ----------
    path : path-like
        A model of ``clutchlab train`` (``model.json``, its ``model.npz`` beside it), a fit of
        ``clutchlab fit-physics``, a physics description (``PhysicsPredictor.save``), a
        parameter file of a design (``clutchlab params --out``) or an FMI 2.0 co-simulation
        FMU whose inputs are named after the canonical signals (``clutchlab export-fmu``).
    substeps : int, optional
        Physics models: ROS2 steps per sample (default 4, what ``clutchlab evaluate``
        scores with). Refused for an ML model, which has none.

    Returns
    -------
    LoadedModel

    Raises
    ------
    ModelError
        The file cannot be read, is none of these kinds, or its content is not valid (every
        problem listed, naming the file).
    """
    from ..physics.fmu.export import physics_source
    from ..physics.settings import MAX_SUBSTEPS, is_integer
    from ..residual_ml import PhysicsPredictor, check_model, load_model, no_substeps_message

    path = Path(path)
    if path.is_file() and zipfile.is_zipfile(path):
        return _fmu(path, substeps)
    doc = read_json_object(path)
    if doc is None:
        raise ModelError(
            f"{path}: not a model file (it is missing, or neither a JSON object nor an FMU)"
        )
    kind = model_doc_kind(doc)
    if kind == "ml":  # a residual_ml model; the loader checks the rest
        if substeps is not None:
            raise ModelError(no_substeps_message(path))
        model = load_model(path)
        check_model(model, str(path))
        name = _variant_name(model)
        trained = tuple(getattr(model, "train_experiments_", ()) or ())
        return LoadedModel(model, f"{name} model (clutchlab train)", trained)
    steps = 4 if substeps is None else substeps
    if not is_integer(steps) or not 1 <= steps <= MAX_SUBSTEPS:
        raise ModelError(f"substeps {steps!r} is not an integer in 1..{MAX_SUBSTEPS}")
    if kind == "physics":
        model = PhysicsPredictor.load(path)
        if substeps is not None:
            model = PhysicsPredictor(model.effects, model.params, steps, model.train_experiments)
        return LoadedModel(model, "physics model", model.train_experiments)
    try:
        circuit, params = physics_source(path)
    except ClutchlabError as exc:
        raise _refused(
            path,
            "not a model clutchlab can predict with (a `clutchlab train` model.json, a "
            "`fit-physics` result or a `params --out` design file)",
            exc,
        ) from exc
    trained = tuple(doc.get("train") or ()) if isinstance(doc.get("train"), list) else ()
    kind = "fitted physics model (clutchlab fit-physics)" if trained else "physics design"
    model = PhysicsPredictor(tuple(circuit.effect_names), params.changed(), steps, trained)
    return LoadedModel(model, kind, trained)


def _fmu(path: Path, substeps: int | None) -> LoadedModel:
    """An FMI 2.0 co-simulation FMU (``clutchlab export-fmu``'s, or one whose inputs are
    named after the canonical signals), simulated with FMPy at its own start values."""
    from ..physics.fmu import FmuPhysics

    if substeps is not None:
        raise ModelError(f"{path}: --substeps is not used by an FMU (its steps are its own)")
    try:
        model = FmuPhysics(path)
    except ClutchlabError as exc:
        raise _refused(
            path,
            "an FMU clutchlab cannot predict with (`clutchlab evaluate --physics-fmu` maps "
            "other input names and sets parameters)",
            exc,
        ) from exc
    return LoadedModel(model, "FMU", ())


def _refused(path: Path, why: str, exc: ClutchlabError) -> ModelError:
    """The error for a model file refused by its loader: the file, why, and every problem
    the loader listed (or its message)."""
    return ModelError(f"{path}: {why}", getattr(exc, "problems", None) or [str(exc)])


def _variant_name(model) -> str:
    """The ``train`` variant a saved estimator's class stands for (residual_ml.VARIANTS;
    ``paper_faithful`` saves as an ``SVCPartitionedGP``), else the class name."""
    from ..residual_ml import VARIANTS

    names = {f.__name__: n for n, f in VARIANTS.items() if isinstance(f, type)}
    return names.get(type(model).__name__, type(model).__name__)


@dataclass(frozen=True)
class ExperimentPrediction:
    """One experiment's prediction.

    Attributes
    ----------
    name, ramp : str
        Experiment name and ramp label (``""`` when the manifest gives none).
    trained : bool
        The model was trained or fitted on this experiment: its scores are in-sample.
    time_s : ndarray
        Sample times (s).
    current_mA : ndarray
        Nominal (dither-free) current (mA).
    measured_bar, predicted_bar : ndarray
        Measured and predicted clutch pressure per sample (bar).
    std_bar : ndarray or None
        Predictive standard deviation (bar), when asked for and the model gives one.
    metrics : dict of str to float
        ``rmse_bar``, ``mae_bar``, ``max_abs_bar`` (bar) and ``fit_pct`` (%) of the
        dither-period means, as ``clutchlab evaluate`` scores.
    period_samples : float
        Samples per dither period, the window of those means (1.0 without a dither: the
        scores are then those of the raw signal).
    averaging : dict or None
        That window in words and units (:func:`~.averaging.averaging_window`: samples, ms,
        the dither frequency it is the period of, and whether the log has a dither).
    """

    name: str
    ramp: str
    trained: bool
    time_s: np.ndarray
    current_mA: np.ndarray
    measured_bar: np.ndarray
    predicted_bar: np.ndarray
    std_bar: np.ndarray | None
    metrics: dict[str, float]
    period_samples: float
    averaging: dict | None = None

    def columns(self) -> dict[str, np.ndarray]:
        """The per-sample table: time (s), nominal current (mA), measured, predicted,
        residual = predicted − measured and (when present) std, all in bar."""
        cols = {
            "time_s": self.time_s,
            "current_nominal_mA": self.current_mA,
            "clutch_pressure_bar": self.measured_bar,
            "predicted_bar": self.predicted_bar,
            "residual_bar": self.predicted_bar - self.measured_bar,
        }
        if self.std_bar is not None:
            cols["std_bar"] = self.std_bar
        return cols


def predict_traces(
    loaded: LoadedModel,
    traces: Iterable[Trace],
    *,
    with_std: bool = False,
    progress=None,
) -> tuple[list[ExperimentPrediction], float]:
    """Predict every trace with a loaded model and score it against the measured pressure.

    Parameters
    ----------
    loaded : LoadedModel
        From :func:`load_predictor`.
    traces : iterable of Trace
        The experiments to predict.
    with_std : bool
        Also the predictive standard deviation (bar); refused when the model has none.
    progress : callable, optional
        Wraps the iterable of traces (e.g. ``tqdm``).

    Returns
    -------
    (list of ExperimentPrediction, float)
        The predictions, and the wall time of the predictions alone (s).

    Raises
    ------
    ModelError
        ``with_std`` for a model without a predictive std.
    DataError
        From the model, naming the experiment (e.g. a signal it needs is not logged).
    """
    if with_std:
        loaded.check_std()
    trained = set(loaded.train_experiments)
    items = list(traces)
    out, wall = [], 0.0
    for tr in progress(items) if progress else items:
        t0 = time.perf_counter()
        if with_std:
            mean, std = loaded.model.predict(tr, return_std=True)
        else:
            mean, std = loaded.model.predict(tr), None
        wall += time.perf_counter() - t0
        mean = np.asarray(mean, dtype=float)
        measured = np.asarray(tr.get("clutch_pressure_bar"), dtype=float)
        n = dither_period_samples(tr)
        metrics = pressure_metrics(dither_period_mean(measured, n), dither_period_mean(mean, n))
        out.append(
            ExperimentPrediction(
                name=tr.name,
                ramp=tr.ramp or "",
                trained=tr.name in trained,
                time_s=np.asarray(tr.time_s, dtype=float),
                current_mA=nominal_current(tr),
                measured_bar=measured,
                predicted_bar=mean,
                std_bar=None if std is None else np.asarray(std, dtype=float),
                metrics=metrics,
                period_samples=n,
                averaging=averaging_window(n, tr.sample_rate_Hz, largest_dither_amp(tr)),
            )
        )
    return out, wall


def overall_metrics(predictions: list[ExperimentPrediction]) -> tuple[dict[str, float], str]:
    """Scores over every sample of the experiments the model was not trained on (all of them
    when it was trained on every one), dither-period means, as ``clutchlab evaluate``
    scores its test ramps.

    Returns
    -------
    (dict of str to float, str)
        ``rmse_bar``, ``mae_bar``, ``max_abs_bar`` (bar), ``fit_pct`` (%), and which
        experiments they cover (``"not trained on"`` or ``"all, in-sample"``).
    """
    held = [p for p in predictions if not p.trained]
    which = "not trained on" if held else "all, in-sample"
    chosen = held or predictions
    measured = [dither_period_mean(p.measured_bar, p.period_samples) for p in chosen]
    predicted = [dither_period_mean(p.predicted_bar, p.period_samples) for p in chosen]
    return pressure_metrics(np.concatenate(measured), np.concatenate(predicted)), which


def prediction_table(predictions: list[ExperimentPrediction]) -> str:
    """A fixed-width table: experiment, ramp, RMSE / MAE / max |e| (bar), fit (%), and
    "train" where the model was trained on the experiment (in-sample); then the scores
    over all experiments (:func:`overall_metrics`)."""
    head = f"{'experiment':24s} {'ramp':8s} {'RMSE (bar)':>10s} {'MAE (bar)':>10s} "
    head += f"{'max|e| (bar)':>12s} {'fit %':>7s}"
    lines = [head]
    for p in predictions:
        m = p.metrics
        lines.append(
            f"{p.name:24s} {p.ramp:8s} {m['rmse_bar']:10.4f} {m['mae_bar']:10.4f} "
            f"{m['max_abs_bar']:12.4f} {m['fit_pct']:7.2f}" + ("  train" if p.trained else "")
        )
    if predictions:
        m, which = overall_metrics(predictions)
        lines.append(
            f"{'all (' + which + ')':33s} {m['rmse_bar']:10.4f} {m['mae_bar']:10.4f} "
            f"{m['max_abs_bar']:12.4f} {m['fit_pct']:7.2f}"
        )
    return "\n".join(lines)
