"""Physics predictors for the hybrid model: the circuit model simulated on a trace.

:class:`PhysicsPredictor` holds a model structure (effects) and parameter values and predicts
clutch pressure (bar) on a trace by simulation; it also exposes the model's other outputs
(pilot pressure, latch state, ...) that the hybrid model may use as features. With no
arguments it is the datasheet-default model — the paper's "physics with default lumped
parameters"; :meth:`PhysicsPredictor.from_fitter` wraps a fitted
:class:`~clutchlab.physics.fit.PhysicsFitter`. Saved as JSON (effects + parameter values).

Any object with ``predict(trace) -> ndarray`` (bar) can serve as the hybrid's physics; one
with ``predict_outputs(trace) -> dict`` also supplies the extra outputs.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..data import Trace, model_file_kind, write_file_atomic
from ..errors import ModelError
from ..physics import CircuitModel, SimulationSettings, simulate
from ..physics.effects import effect_names
from ..physics.fit.fitter import check_savable
from ..physics.settings import MAX_SUBSTEPS, is_integer

__all__ = ["DefaultPhysics", "PhysicsPredictor"]


class PhysicsPredictor:
    """Clutch pressure of the lumped-parameter circuit model, simulated on a trace.

    Parameters
    ----------
    effects : tuple of str or str
        Effects switched on (names of :data:`clutchlab.physics.EFFECTS`; default none); one
        name alone, or names separated by commas, as a string.
    params : mapping of str to float, optional
        Parameter values differing from the datasheet defaults, engineering units.
    substeps : int
        ROS2 steps per sample, 1 to :data:`~clutchlab.physics.settings.MAX_SUBSTEPS`
        (default 4).
    train_experiments : sequence of str
        Experiments the parameter values were fitted on (default none: datasheet values or
        values of unknown origin). A hybrid model on this physics declares them among its
        own training experiments, so the validation protocol refuses it on any of them.

    Attributes
    ----------
    train_experiments_ : list of str
        ``train_experiments`` as a list (the name the validation protocol reads).

    Raises
    ------
    ModelError
        If an effect or parameter name is unknown, or ``substeps`` is not an integer in
        its range.
    """

    def __init__(
        self,
        effects: tuple[str, ...] = (),
        params: Mapping[str, float] | None = None,
        substeps: int = 4,
        train_experiments: tuple[str, ...] = (),
    ) -> None:
        if isinstance(effects, str):  # one name (or "a, b"), not a sequence of letters
            effects = effect_names(effects, "PhysicsPredictor effects")
        self.effects = tuple(effects)
        self.params = dict(params or {})
        if not is_integer(substeps) or not 1 <= substeps <= MAX_SUBSTEPS:
            raise ModelError(
                f"PhysicsPredictor substeps {substeps!r} is not an integer in 1..{MAX_SUBSTEPS} "
                "(ROS2 steps per sample)"
            )
        self.substeps = int(substeps)
        if isinstance(train_experiments, str):
            raise ModelError("train_experiments must be a sequence of experiment names")
        self.train_experiments = tuple(str(n) for n in train_experiments)
        self._model = CircuitModel().with_effects(*self.effects)
        self._params = self._model.params(**self.params)

    def __repr__(self) -> str:
        trained = ""
        if self.train_experiments:
            trained = f", train_experiments={self.train_experiments!r}"
        return (
            f"PhysicsPredictor(effects={self.effects!r}, params={self.params!r}, "
            f"substeps={self.substeps}{trained})"
        )

    @property
    def train_experiments_(self) -> list[str]:
        """Experiments the parameter values were fitted on (empty if not known)."""
        return list(self.train_experiments)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, PhysicsPredictor) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_dict(), sort_keys=True))

    def __getstate__(self) -> dict:
        return self.to_dict()

    def __setstate__(self, state: dict) -> None:
        self.__init__(
            tuple(state["effects"]),
            state["params"],
            state["substeps"],
            tuple(state.get("train_experiments", ())),
        )

    @classmethod
    def from_fitter(cls, fitter, substeps: int = 4) -> PhysicsPredictor:
        """The fitted model of a :class:`~clutchlab.physics.fit.PhysicsFitter`, with the
        experiments it was fitted on (``result_.train``).

        Raises
        ------
        sklearn.exceptions.NotFittedError
            If the fitter is not fitted.
        ModelError
            If the fitted model has components other than the base circuit's (a
            PhysicsPredictor rebuilds the base circuit with the effects).
        """
        fitter._check_fitted()
        model, params = fitter.model_, fitter.params_
        check_savable(model)  # a predictor is its effects and values: no custom components
        result = getattr(fitter, "result_", None)
        trained = tuple(getattr(result, "train", None) or ())
        return cls(tuple(model.effect_names), params.changed(), substeps, trained)

    def predict_outputs(self, trace: Trace) -> dict[str, np.ndarray]:
        """All model outputs on ``trace`` (name → per-sample array, units of
        :data:`clutchlab.physics.OUTPUTS`: pressures in bar, latch state 0–1, ...)."""
        if not isinstance(trace, Trace):
            raise ModelError(f"expected a Trace, got {type(trace).__name__}")
        res = simulate(self._model, self._params, trace, SimulationSettings(substeps=self.substeps))
        return {k: np.asarray(v, dtype=float) for k, v in res.outputs.items()}

    def predict(self, trace: Trace) -> np.ndarray:
        """Clutch pressure as the sensor reads it, bar, per sample of ``trace``."""
        return self.predict_outputs(trace)["clutch_pressure_bar"]

    def to_dict(self) -> dict:
        """JSON-ready description (``train_experiments`` only when there are some)."""
        d = {
            "kind": "PhysicsPredictor",
            "effects": list(self.effects),
            "params": {k: float(v) for k, v in self.params.items()},
            "substeps": self.substeps,
        }
        if self.train_experiments:
            d["train_experiments"] = list(self.train_experiments)
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> PhysicsPredictor:
        """Inverse of :meth:`to_dict`."""
        if d.get("kind") != "PhysicsPredictor":
            raise ModelError(f"not a PhysicsPredictor description: kind={d.get('kind')!r}")
        trained = tuple(d.get("train_experiments", ()))  # descriptions before it: none
        return cls(tuple(d["effects"]), dict(d["params"]), int(d["substeps"]), trained)

    def save(self, path: str | Path) -> None:
        """Write :meth:`to_dict` as JSON to ``path``."""
        text = json.dumps(self.to_dict(), indent=2) + "\n"
        write_file_atomic(path, text.encode("utf-8"), overwrite=True)

    @classmethod
    def load(cls, path: str | Path) -> PhysicsPredictor:
        """Read a JSON written by :meth:`save`.

        Raises
        ------
        ModelError
            If the file cannot be read or is not JSON, naming the file.
        ModelFileError
            (a ModelError) If it is not a valid PhysicsPredictor description, listing every
            problem by key (missing keys, unknown effects or parameters, bad substeps).
        """
        from .model_check import check_physics_document

        try:
            doc = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError) as exc:
            raise ModelError(f"cannot read physics model {path}: {exc}") from None
        check_physics_document(doc, str(path))
        return cls.from_dict(doc)

    @staticmethod
    def describes(path: str | Path) -> bool:
        """Whether ``path`` holds a JSON object that says it is a PhysicsPredictor
        (``"kind": "PhysicsPredictor"``), valid or not; False when it cannot be read."""
        return model_file_kind(path) == "physics"


def DefaultPhysics(substeps: int = 4) -> PhysicsPredictor:
    """Deprecated: ``PhysicsPredictor(substeps=substeps)``, the datasheet-default model.

    The name is also :class:`clutchlab.validation.DefaultPhysics`, the ``physics_default``
    variant (an estimator); this function returns a :class:`PhysicsPredictor` and is kept
    only so existing scripts run.

    Parameters
    ----------
    substeps : int
        ROS2 steps per sample (default 4).
    """
    warnings.warn(
        "clutchlab.residual_ml.DefaultPhysics() is deprecated: use PhysicsPredictor() "
        "(the datasheet-default model); clutchlab.validation.DefaultPhysics is the "
        "physics_default variant",
        DeprecationWarning,
        stacklevel=2,
    )
    return PhysicsPredictor((), None, substeps)
